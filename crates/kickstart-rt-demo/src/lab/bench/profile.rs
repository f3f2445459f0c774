//! Where one measured task's GPU time went: its timed passes grouped by scope and pass, for the
//! profile that each build, refit and TLAS figure of `ksrt bench` carries.

use kickstart_rt as ksrt;
use serde::Serialize;

/// The passes of one (scope, pass) pair in one task.
#[derive(Debug, Clone, Serialize, PartialEq)]
pub struct PassProfile {
    /// What the SDK was doing (`ingest`, `blas build`, `tlas build`, …).
    pub scope: String,
    /// The pass within it (e.g. `radix sort`, `lbvh climb`).
    pub pass: String,
    /// Dispatch groups timed under this pair.
    pub passes: u32,
    /// Their summed GPU time, milliseconds.
    pub ms: f64,
}

/// Groups `passes` by (scope, pass), in the order each pair first ran.
pub fn profile(passes: &[ksrt::PassTiming]) -> Vec<PassProfile> {
    let mut out: Vec<PassProfile> = Vec::new();
    for p in passes {
        match out
            .iter_mut()
            .find(|q| q.scope == p.label && q.pass == p.pass)
        {
            Some(q) => {
                q.passes += 1;
                q.ms += p.ms;
            }
            None => out.push(PassProfile {
                scope: p.label.to_string(),
                pass: p.pass.to_string(),
                passes: 1,
                ms: p.ms,
            }),
        }
    }
    out
}

/// The passes a figure's span covers (labels starting with one of `span`, as
/// [`ksrt::GpuTimings::span_ms`] picks them): the profile of a figure lists what it timed, not
/// other work of the same task (the lighting cache's allocation passes that registering
/// thousands of instances records beside a TLAS build).
pub fn within(passes: Vec<ksrt::PassTiming>, span: &[&str]) -> Vec<ksrt::PassTiming> {
    passes
        .into_iter()
        .filter(|p| span.iter().any(|s| p.label.starts_with(s)))
        .collect()
}

/// One line: `pass ms (count)` for each entry, largest first.
pub fn show(profile: &[PassProfile]) -> String {
    let mut sorted: Vec<&PassProfile> = profile.iter().collect();
    sorted.sort_by(|a, b| b.ms.total_cmp(&a.ms));
    sorted
        .iter()
        .map(|p| format!("{}/{} {:.3} ms ({}×)", p.scope, p.pass, p.ms, p.passes))
        .collect::<Vec<_>>()
        .join(", ")
}

#[cfg(test)]
mod tests {
    use super::*;

    fn pass(label: &'static str, pass: &'static str, ms: f64) -> ksrt::PassTiming {
        ksrt::PassTiming {
            label,
            pass,
            start_ms: 0.0,
            ms,
        }
    }

    #[test]
    fn passes_group_by_scope_and_pass_in_first_seen_order() {
        let p = profile(&[
            pass("ingest", "decode", 0.5),
            pass("blas build", "radix sort", 0.25),
            pass("blas build", "radix sort", 0.5),
            pass("blas build", "climb", 1.0),
        ]);
        assert_eq!(p.len(), 3);
        assert_eq!(
            (p[1].pass.as_str(), p[1].passes, p[1].ms),
            ("radix sort", 2, 0.75)
        );
        assert!(show(&p).starts_with("blas build/climb 1.000 ms (1×)"));
    }

    #[test]
    fn a_profile_keeps_only_the_passes_of_its_span() {
        let passes = vec![
            pass("cache allocation", "cache write", 1.8),
            pass("tlas build", "radix sort", 0.1),
            pass("ingest", "ingest", 0.2),
            pass("tlas build", "lbvh climb", 0.05),
        ];
        let kept = within(passes.clone(), &["tlas build"]);
        assert_eq!(
            kept.iter().map(|p| p.pass).collect::<Vec<_>>(),
            ["radix sort", "lbvh climb"]
        );
        let kept = within(passes, &["ingest", "tlas"]);
        assert_eq!(kept.len(), 3);
        assert!(kept.iter().all(|p| p.label != "cache allocation"));
    }
}
