#!/usr/bin/env python3
"""Writes wgsl/<variant>.wgsl, the ray batch pass sources traced in session 29's device calls
(each one file: scene types + traversal + batch kernel, joined by newlines, as the uncommitted
KSRT_DEV_TRACE_WGSL hook read them). Sources: the shaders of commit 064bed9, the cut-off try's
loop (dev-schedule.diff, applied to a temporary copy) with schedule/*.wgsl, fetch/kernel.wgsl,
and the edits below. Run from anywhere inside the repository: python3 gen.py"""
import pathlib
import subprocess
import tempfile

HERE = pathlib.Path(__file__).resolve().parent
BASE = '064bed9'
SH = 'crates/kickstart-rt/shaders/'


def at_base(name):
    return subprocess.check_output(['git', 'show', f'{BASE}:{SH}{name}'], cwd=HERE).decode()


def replaced(text, old, new):
    assert old in text, old[:60]
    return text.replace(old, new)


TYPES, TRAV, RAYS = at_base('scene_types.wgsl'), at_base('traverse.wgsl'), at_base('trace_rays.wgsl')


def try_traverse():
    """traverse.wgsl of the cut-off try: the base's with dev-schedule.diff applied."""
    with tempfile.TemporaryDirectory() as tmp:
        path = pathlib.Path(tmp) / SH / 'traverse.wgsl'
        path.parent.mkdir(parents=True)
        path.write_text(TRAV)
        subprocess.run(['git', 'apply', '--include=' + SH + 'traverse.wgsl',
                        str(HERE / 'dev-schedule.diff')], cwd=tmp, check=True)
        return path.read_text()


# Call 1: postponed triangle tests.
NEW = try_traverse()
NOW = (HERE / 'schedule/traverse_schedule_now.wgsl').read_text()
SG = (HERE / 'schedule/traverse_schedule_subgroup.wgsl').read_text()


def sg(num, den):
    s = replaced(SG, 'const RT_POSTPONE_NUM: u32 = 1u;', f'const RT_POSTPONE_NUM: u32 = {num}u;')
    return replaced(s, 'const RT_POSTPONE_DEN: u32 = 2u;', f'const RT_POSTPONE_DEN: u32 = {den}u;')


SPEC = replaced(replaced(replaced(NEW, """            if pending != 0u || sp == 0u {
                break;
            }""", """            if sp == 0u {
                break;
            }
            // Speculative: an invocation told to wait with a pending leaf goes on through
            // inner nodes of the same BLAS.
            if pending != 0u && (!waited || sp <= blas_sp || (rt_stack[sp - 1u].x & RT_LEAF_BIT) != 0u) {
                break;
            }"""), """        if !rt_test_pending(pending != 0u, pending == 0u && sp > 0u) {
            continue;
        }""", """        let go = rt_test_pending(pending != 0u, pending == 0u && sp > 0u);
        waited = !go;
        if !go {
            continue;
        }"""), "    var visits = 0u;\n    loop {", "    var visits = 0u;\n    var waited = false;\n    loop {")

# Call 2: extra work per BLAS node step, hidden behind params.pad (0 at run time).
NODE_END = """            n3 = rt_blas_nodes[base + 3u];
        } else {"""


def extra_loads(k):
    s = "            n3 = rt_blas_nodes[base + 3u];\n            let xb = base + params.pad;\n"
    for i in range(k):
        tgt = ['n0', 'n1', 'n2', 'n3'][i % 4]
        fn = 'min' if i % 2 == 0 else 'max'
        s += f"            let e{i} = rt_blas_nodes[xb + {i % 4}u];\n"
        s += f"            {tgt} = vec4<f32>({fn}({tgt}.xyz, e{i}.xyz), {tgt}.w);\n"
    return replaced(TRAV, NODE_END, s + "        } else {")


ALU = replaced(TRAV, NODE_END, """            n3 = rt_blas_nodes[base + 3u];
            // 32 dependent FMAs that cancel at run time (params.pad == 0).
            var z = bitcast<f32>(params.pad) * n0.x;
            for (var j = 0u; j < 32u; j += 1u) { z = fma(z, 1.0001, bitcast<f32>(params.pad)); }
            n0.x = n0.x + z;
        } else {""")
POP = "        let popped = rt_stack_load(sp);"
STK = replaced(TRAV, POP, POP + "\n        let px = rt_stack_load(sp - (params.pad & 1u)); // == popped at run time"
               "\n        if px.node != popped.node { t_max = -1.0; }")

# Call 4: dynamic ray fetch (fetch/kernel.wgsl around the base loop's body).
BODY_START = "    while sp > 0u && visits < RT_MAX_VISITS {\n"
BODY_END = "    }\n    if best_inst == RT_NO_INDEX {\n        return miss;"
BODY = TRAV[TRAV.index(BODY_START) + len(BODY_START):TRAV.index(BODY_END)]
assert BODY.count("break;") == 1
BODY = replaced(BODY, "                        if any_hit {\n                            break;\n                        }",
                "                        if any_hit {\n                            done = true;\n                            continue;\n                        }")
KERNEL = (HERE / 'fetch/kernel.wgsl').read_text()


def fetch(num, den):
    k = KERNEL.replace('RT_REFILL_NUM_V', f'{num}u').replace('RT_REFILL_DEN_V', f'{den}u')
    return '\n'.join([TYPES, TRAV, replaced(k, '    // BODY\n', BODY)])


# Call 6: 32-byte quantised nodes (the pool written by quant/dev_quantize.wgsl).
Q32 = replaced(TRAV, """            let base = (node_base + entry) * 4u;
            n0 = rt_blas_nodes[base];
            n1 = rt_blas_nodes[base + 1u];
            n2 = rt_blas_nodes[base + 2u];
            n3 = rt_blas_nodes[base + 3u];""", """            let base = (node_base + entry) * 4u;
            // 32-byte quantised node (dev_quantize.wgsl): o + q·s per plane.
            let qa = bitcast<vec4<u32>>(rt_blas_nodes[base]);
            let qb = bitcast<vec4<u32>>(rt_blas_nodes[base + 1u]);
            let qo = bitcast<vec3<f32>>(qa.xyz & vec3<u32>(0xffffff00u));
            let qs = bitcast<vec3<f32>>((qa.xyz & vec3<u32>(0xffu)) << vec3<u32>(23u));
            let lmin = qo + vec3<f32>(f32(qb.y & 0xffu), f32((qb.y >> 8u) & 0xffu), f32((qb.y >> 16u) & 0xffu)) * qs;
            let lmax = qo + vec3<f32>(f32(qb.y >> 24u), f32(qb.z & 0xffu), f32((qb.z >> 8u) & 0xffu)) * qs;
            let rmin = qo + vec3<f32>(f32((qb.z >> 16u) & 0xffu), f32(qb.z >> 24u), f32(qb.w & 0xffu)) * qs;
            let rmax = qo + vec3<f32>(f32((qb.w >> 8u) & 0xffu), f32((qb.w >> 16u) & 0xffu), f32(qb.w >> 24u)) * qs;
            n0 = vec4<f32>(lmin, bitcast<f32>(qa.w));
            n1 = vec4<f32>(lmax, bitcast<f32>(qb.x));
            n2 = vec4<f32>(rmin, 0.0);
            n3 = vec4<f32>(rmax, 0.0);""")

VARIANTS = {
    'd0': [TYPES, TRAV, RAYS],
    'now': [TYPES, NEW, NOW, RAYS],
    'sg12': [TYPES, NEW, sg(1, 2), RAYS],
    'sg14': [TYPES, NEW, sg(1, 4), RAYS],
    'sg34': [TYPES, NEW, sg(3, 4), RAYS],
    'sg11': [TYPES, NEW, sg(1, 1), RAYS],
    'spec11': [TYPES, SPEC, sg(1, 1), RAYS],
    'spec12': [TYPES, SPEC, sg(1, 2), RAYS],
    'ld2': [TYPES, extra_loads(2), RAYS],
    'ld4': [TYPES, extra_loads(4), RAYS],
    'alu': [TYPES, ALU, RAYS],
    'stk': [TYPES, STK, RAYS],
    'q32': [TYPES, Q32, RAYS],
}
out = HERE / 'wgsl'
out.mkdir(exist_ok=True)
for name, parts in VARIANTS.items():
    (out / f'{name}.wgsl').write_text('\n'.join(parts))
for name, num, den in [('f12', 1, 2), ('f14', 1, 4), ('f34', 3, 4), ('f18', 1, 8), ('f11', 1, 1)]:
    (out / f'{name}.wgsl').write_text(fetch(num, den))
print(f'wrote {len(VARIANTS) + 5} variants to {out}')
