//! How a BLAS is built: the application's [`BuildHint`] resolved once, at registration, into
//! the tree the builder makes and the refit it takes.

use crate::tasks::BuildHint;

/// The tree a BLAS build makes; every later decision (the build's passes, how a refit runs,
/// whether an update can decode its own triangles) matches on it.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub(crate) enum BuildStrategy {
    /// Triangles clustered while climbing the Karras tree (H-PLOC), leaves collapsed by SAH up
    /// to [`BuildHint::FAST_TRACE_MAX_LEAF`] triangles; a refit gathers and climbs.
    FastTrace,
    /// The Karras tree, one triangle a leaf, its nodes written from leaf ranges; a refit runs
    /// from the same ranges.
    FastBuild,
}

impl BuildStrategy {
    /// The strategy of a geometry registered with `hint` and `allow_update`: `Auto` is
    /// fast-build for updatable geometry (it is refit often) and fast-trace otherwise.
    pub fn of(hint: BuildHint, allow_update: bool) -> Self {
        match hint {
            BuildHint::PreferFastTrace => BuildStrategy::FastTrace,
            BuildHint::PreferFastBuild => BuildStrategy::FastBuild,
            BuildHint::Auto if allow_update => BuildStrategy::FastBuild,
            BuildHint::Auto => BuildStrategy::FastTrace,
        }
    }

    /// Largest leaf the build makes, in triangles.
    pub fn max_leaf(self) -> u32 {
        match self {
            BuildStrategy::FastTrace => BuildHint::FAST_TRACE_MAX_LEAF,
            BuildStrategy::FastBuild => 1,
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn auto_follows_allow_update_and_the_preferences_do_not() {
        use BuildStrategy::*;
        assert_eq!(BuildStrategy::of(BuildHint::Auto, false), FastTrace);
        assert_eq!(BuildStrategy::of(BuildHint::Auto, true), FastBuild);
        for update in [false, true] {
            assert_eq!(
                BuildStrategy::of(BuildHint::PreferFastTrace, update),
                FastTrace
            );
            assert_eq!(
                BuildStrategy::of(BuildHint::PreferFastBuild, update),
                FastBuild
            );
        }
        assert_eq!(FastTrace.max_leaf(), BuildHint::FAST_TRACE_MAX_LEAF);
        assert_eq!(FastBuild.max_leaf(), 1);
    }
}
