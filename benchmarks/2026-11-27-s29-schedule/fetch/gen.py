# Generates the dynamic-ray-fetch variants of the ray batch pass (session 29, experiment).
import pathlib, re, sys
sh = 'crates/kickstart-rt/shaders/'
types = open(sh + 'scene_types.wgsl').read()
trav = open(sh + 'traverse.wgsl').read()
start = "    while sp > 0u && visits < RT_MAX_VISITS {\n"
end = "    }\n    if best_inst == RT_NO_INDEX {\n        return miss;"
i = trav.index(start) + len(start)
j = trav.index(end)
body = trav[i:j]
assert body.count("break;") == 1
body = body.replace("                        if any_hit {\n                            break;\n                        }",
                    "                        if any_hit {\n                            done = true;\n                            continue;\n                        }")
assert "break;" not in body
KERNEL = open('benchmarks/2026-11-27-s29-schedule/fetch/kernel.wgsl').read()
out = pathlib.Path('benchmarks/2026-11-27-s29-schedule/wgsl')
for name, num, den in [('f12', 1, 2), ('f14', 1, 4), ('f34', 3, 4), ('f18', 1, 8), ('f11', 1, 1)]:
    k = KERNEL.replace('RT_REFILL_NUM_V', f'{num}u').replace('RT_REFILL_DEN_V', f'{den}u').replace('    // BODY\n', body)
    (out / f'{name}.wgsl').write_text('\n'.join([types, trav, k]))
print('ok')
