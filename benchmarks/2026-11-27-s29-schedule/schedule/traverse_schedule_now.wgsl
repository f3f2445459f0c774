// Triangle scheduling for traverse.wgsl without subgroup operations: a pending leaf's next
// triangle is tested in the same iteration.
fn rt_test_pending(has_pending: bool, can_pop: bool) -> bool {
    return has_pending;
}
