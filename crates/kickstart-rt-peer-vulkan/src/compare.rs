//! Ours against theirs, ray by ray (pure CPU).

use crate::Hit;

/// Two hit distances closer than this, relative to the larger, count as equal: a **tie**.
///
/// Ties are where two tracers may legitimately report different triangles: a ray through a
/// shared edge or vertex (both triangles are hit at the same point), or coincident / overlapping
/// triangles (the same surface twice). Our tracer breaks a tie deterministically (equal t → lowest
/// instance, then lowest primitive); the hardware's rule is unspecified, and its t is computed by
/// another intersection algorithm, so "equal" has to allow a few ulps of rounding: 1e-4 relative
/// is far below the size of a triangle as seen from the camera in the bench scenes, and far above
/// f32 rounding of t.
pub const TIE_REL_TOLERANCE: f32 = 1e-4;

/// Both tracers hit the same triangle (or tie) but their distances differ by more than this,
/// relative to the larger: a **distance mismatch**, counted apart from disagreements (the same
/// bound as `ksrt bench`'s check against the CPU oracle).
pub const DISTANCE_REL_TOLERANCE: f32 = 1e-3;

/// What the query asked for, which decides what has to match.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum QueryKind {
    /// Closest hit: hit/miss, and the triangle (up to ties) must match.
    Closest,
    /// Any hit (occlusion): only hit/miss must match; each tracer may stop at any occluder.
    Any,
}

/// How one ray's two results relate.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Outcome {
    /// Both missed, or both hit the same (instance, primitive) at distances within
    /// [`DISTANCE_REL_TOLERANCE`], or (any-hit) both hit something.
    Agree,
    /// Both hit, different triangles, distances equal within [`TIE_REL_TOLERANCE`]: agreement.
    Tie,
    /// Both hit the same triangle (or tie), but the distances differ by more than
    /// [`DISTANCE_REL_TOLERANCE`]: agreement on the hit, counted separately.
    DistanceMismatch,
    /// One hit, the other missed: a disagreement.
    HitMiss,
    /// Both hit (closest-hit query), different triangles at different distances: a disagreement.
    DifferentTriangle,
}

impl Outcome {
    /// Whether this outcome is a disagreement (hit vs miss, or another triangle beyond a tie).
    pub fn disagrees(self) -> bool {
        matches!(self, Outcome::HitMiss | Outcome::DifferentTriangle)
    }
}

fn close(a: f32, b: f32, rel: f32) -> bool {
    // `<=` is false for NaN: a NaN distance never counts as close.
    let scale = a.abs().max(b.abs());
    (a - b).abs() <= rel * scale
}

/// Classifies one ray: `ours` from kickstart-rt, `theirs` from the peer.
///
/// Closest hit: disagreement = hit vs miss, or both hit on a different (instance, primitive)
/// unless the distances are equal within [`TIE_REL_TOLERANCE`] (a tie, see there). Any hit:
/// disagreement = hit vs miss only. Among agreeing hits, a same-triangle (or tie) pair whose
/// distances differ by more than [`DISTANCE_REL_TOLERANCE`] is a [`Outcome::DistanceMismatch`]
/// (closest hit only: an any-hit query's occluders may be at any distance).
pub fn classify(ours: &Hit, theirs: &Hit, kind: QueryKind) -> Outcome {
    match (ours.is_hit(), theirs.is_hit()) {
        (false, false) => Outcome::Agree,
        (true, false) | (false, true) => Outcome::HitMiss,
        (true, true) if kind == QueryKind::Any => Outcome::Agree,
        (true, true) => {
            let same = ours.instance == theirs.instance && ours.primitive == theirs.primitive;
            if same {
                if close(ours.t, theirs.t, DISTANCE_REL_TOLERANCE) {
                    Outcome::Agree
                } else {
                    Outcome::DistanceMismatch
                }
            } else if close(ours.t, theirs.t, TIE_REL_TOLERANCE) {
                Outcome::Tie
            } else {
                Outcome::DifferentTriangle
            }
        }
    }
}

/// Counts over a batch.
#[derive(Debug, Clone, Copy, Default, PartialEq, Eq)]
pub struct Agreement {
    /// Rays compared.
    pub rays: u64,
    /// Disagreements: `hit_miss + different_triangle`.
    pub disagreements: u64,
    /// One hit, the other missed.
    pub hit_miss: u64,
    /// Both hit different triangles at distances beyond a tie.
    pub different_triangle: u64,
    /// Both hit different triangles at equal distances (agreeing).
    pub ties: u64,
    /// Same triangle (or tie) at distances beyond [`DISTANCE_REL_TOLERANCE`] (agreeing on the
    /// hit; counted apart).
    pub distance_mismatches: u64,
}

impl Agreement {
    /// Disagreements as a fraction of the rays (0 for an empty batch).
    pub fn disagreement_fraction(&self) -> f64 {
        if self.rays == 0 {
            0.0
        } else {
            self.disagreements as f64 / self.rays as f64
        }
    }
}

/// Compares two batches ray by ray. Rays beyond the shorter batch count as hit-vs-miss
/// disagreements when the longer one has a hit there (a truncated batch must not look better).
pub fn compare_hits(ours: &[Hit], theirs: &[Hit], kind: QueryKind) -> Agreement {
    let mut a = Agreement::default();
    let n = ours.len().max(theirs.len());
    for i in 0..n {
        let o = ours.get(i).unwrap_or(&Hit::MISS);
        let t = theirs.get(i).unwrap_or(&Hit::MISS);
        let outcome = classify(o, t, kind);
        a.rays += 1;
        match outcome {
            Outcome::Agree => {}
            Outcome::Tie => a.ties += 1,
            Outcome::DistanceMismatch => a.distance_mismatches += 1,
            Outcome::HitMiss => a.hit_miss += 1,
            Outcome::DifferentTriangle => a.different_triangle += 1,
        }
        a.disagreements += u64::from(outcome.disagrees());
    }
    a
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn misses_agree_and_hit_vs_miss_disagrees() {
        let h = Hit::at(1.0, 0, 5);
        assert_eq!(
            classify(&Hit::MISS, &Hit::MISS, QueryKind::Closest),
            Outcome::Agree
        );
        assert_eq!(
            classify(&h, &Hit::MISS, QueryKind::Closest),
            Outcome::HitMiss
        );
        assert_eq!(classify(&Hit::MISS, &h, QueryKind::Any), Outcome::HitMiss);
    }

    #[test]
    fn same_triangle_agrees_and_far_distances_are_mismatches() {
        let a = Hit::at(2.0, 3, 7);
        assert_eq!(
            classify(&a, &Hit::at(2.0001, 3, 7), QueryKind::Closest),
            Outcome::Agree
        );
        assert_eq!(
            classify(&a, &Hit::at(2.1, 3, 7), QueryKind::Closest),
            Outcome::DistanceMismatch
        );
        assert!(!Outcome::DistanceMismatch.disagrees());
    }

    #[test]
    fn other_triangle_is_a_tie_only_at_equal_distance() {
        let a = Hit::at(10.0, 0, 1);
        // Shared edge: the other triangle, the same point up to rounding.
        assert_eq!(
            classify(&a, &Hit::at(10.0005, 0, 2), QueryKind::Closest),
            Outcome::Tie
        );
        // Another instance (coincident geometry) at the same distance: also a tie.
        assert_eq!(
            classify(&a, &Hit::at(10.0, 4, 1), QueryKind::Closest),
            Outcome::Tie
        );
        assert_eq!(
            classify(&a, &Hit::at(10.01, 0, 2), QueryKind::Closest),
            Outcome::DifferentTriangle
        );
        // A NaN distance is never a tie.
        assert_eq!(
            classify(&a, &Hit::at(f32::NAN, 0, 2), QueryKind::Closest),
            Outcome::DifferentTriangle
        );
    }

    #[test]
    fn any_hit_only_compares_hit_or_miss() {
        let a = Hit::at(0.1, 0, 1);
        let b = Hit::at(0.9, 2, 8);
        assert_eq!(classify(&a, &b, QueryKind::Any), Outcome::Agree);
        assert_eq!(
            classify(&a, &b, QueryKind::Closest),
            Outcome::DifferentTriangle
        );
    }

    #[test]
    fn batch_counts() {
        let ours = [
            Hit::at(1.0, 0, 0),
            Hit::MISS,
            Hit::at(1.0, 0, 1),
            Hit::at(1.0, 0, 2),
            Hit::at(1.0, 0, 3),
        ];
        let theirs = [
            Hit::at(1.0, 0, 0),
            Hit::at(1.0, 0, 0),
            Hit::at(1.0, 0, 9),
            Hit::at(3.0, 0, 2),
        ];
        let a = compare_hits(&ours, &theirs, QueryKind::Closest);
        assert_eq!(
            a,
            Agreement {
                rays: 5,
                disagreements: 2,
                hit_miss: 2,
                different_triangle: 0,
                ties: 1,
                distance_mismatches: 1,
            }
        );
        assert!((a.disagreement_fraction() - 0.4).abs() < 1e-12);
        assert_eq!(
            compare_hits(&[], &[], QueryKind::Any).disagreement_fraction(),
            0.0
        );
    }
}
