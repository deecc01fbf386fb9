"""One pass of a small Cornell box with Mitsuba 3 (CPU, scalar_rgb): the seed and the EXR file come from the bias
suite (welch_mitsuba.toml); KEY=VALUE arguments change the integrator (max_depth, rr_depth) or the light's
radiance scale (light_scale), which is how a suite plants a change to find.

    python render.py --seed 7 --out pass.exr [--spp 4] [max_depth=3]
"""

import argparse

import mitsuba as mi

mi.set_variant("scalar_rgb")

parser = argparse.ArgumentParser(description=__doc__)
parser.add_argument("--seed", type=int, required=True)
parser.add_argument("--out", required=True)
parser.add_argument("--spp", type=int, default=1)
parser.add_argument("changes", nargs="*", metavar="KEY=VALUE")
args = parser.parse_args()
changes = dict(change.split("=", 1) for change in args.changes)

scene = mi.cornell_box()
scene["sensor"]["film"].update(width=32, height=32, rfilter={"type": "box"})  # box: pixels independent
scene["integrator"] = {
    "type": "path",
    "max_depth": int(changes.pop("max_depth", -1)),
    "rr_depth": int(changes.pop("rr_depth", 5)),
}
scene["light"]["emitter"]["radiance"]["value"] = [
    v * float(changes.pop("light_scale", 1.0)) for v in scene["light"]["emitter"]["radiance"]["value"]
]
if changes:
    parser.error(f"unknown change {next(iter(changes))!r}")

image = mi.render(mi.load_dict(scene), spp=args.spp, seed=args.seed)
mi.Bitmap(image).write(args.out)
