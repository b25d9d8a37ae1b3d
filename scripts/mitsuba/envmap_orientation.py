#!/usr/bin/env python3
"""Prints Mitsuba 3's `envmap` radiance for a few world directions of a small synthetic map.

photonfarm's environment light follows Mitsuba 3's orientation convention; the numbers this prints are
restated in shared/src/light/environment.rs (test `radiance_matches_mitsuba_orientation`), so that the test
needs no Mitsuba. Run with Mitsuba 3 installed (`pip install mitsuba`): python3 scripts/mitsuba/envmap_orientation.py
"""
import mitsuba as mi

mi.set_variant("scalar_rgb")

# Texel (x, y) of the 8 x 5 map holds RGB (x + 1, y + 1, 10 x + y + 1), so that every value names its texel.
W, H = 8, 5
flat = []
for y in range(H):
    for x in range(W):
        flat += [x + 1.0, y + 1.0, 10.0 * x + y + 1.0]
bitmap = mi.Bitmap(mi.TensorXf(flat, shape=(H, W, 3)))

DIRECTIONS = [
    (0, 0, -1), (1, 0, 0), (0, 0, 1), (-1, 0, 0), (0, 1, 0), (0, -1, 0),
    (0.3, 0.5, -0.8), (-0.6, -0.2, 0.4),
]

for name, to_world in [
    ("identity", mi.ScalarTransform4f()),
    ("rotate +90 deg about y", mi.ScalarTransform4f().rotate([0, 1, 0], 90)),
]:
    emitter = mi.load_dict({"type": "envmap", "bitmap": bitmap, "to_world": to_world})
    print(f"to_world: {name}")
    si = mi.SurfaceInteraction3f()
    for d in DIRECTIONS:
        d = mi.ScalarVector3f(d)
        d = d / (d.x**2 + d.y**2 + d.z**2) ** 0.5
        # eval() reads the radiance arriving along -wi: the environment seen looking toward d.
        si.wi = -d
        print(f"  toward ({d.x:+.4f}, {d.y:+.4f}, {d.z:+.4f}): {list(emitter.eval(si))}")
