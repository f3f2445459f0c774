// Triangle scheduling for traverse.wgsl with subgroup operations: an invocation with a pending
// leaf waits (pops nothing) until no invocation of its subgroup can pop a node, or until at
// least RT_POSTPONE_NUM / RT_POSTPONE_DEN of the subgroup's active invocations have a pending
// leaf; then they all test a triangle together.
const RT_POSTPONE_NUM: u32 = 1u;
const RT_POSTPONE_DEN: u32 = 2u;

fn rt_ballot_count(b: vec4<u32>) -> u32 {
    return countOneBits(b.x) + countOneBits(b.y) + countOneBits(b.z) + countOneBits(b.w);
}

fn rt_test_pending(has_pending: bool, can_pop: bool) -> bool {
    let waiting = rt_ballot_count(subgroupBallot(has_pending));
    let lanes = rt_ballot_count(subgroupBallot(true));
    let popping = subgroupAny(can_pop);
    return has_pending && (!popping || waiting * RT_POSTPONE_DEN >= lanes * RT_POSTPONE_NUM);
}
