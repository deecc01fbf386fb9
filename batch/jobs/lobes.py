"""Light components and light groups: which part of the light a bias is in.

Cycles writes light passes that split Combined into components, each estimated by the same paths as Combined:
Diffuse, Glossy and Transmission have Direct, Indirect and Color passes, with Direct and Indirect stored divided by
Color (a ratio, undefined where the colour is zero), so the component to test is (Direct + Indirect) x Color, a
plain sample mean again; Volume Direct, Volume Indirect, Emission and Environment add as they are. Together they
are Combined (measured in Blender 5.0.1: equal to float precision, 4e-8 of the image's sum); ambient occlusion and
the shadow catcher are not components of it. Each light group has its own Combined (``Combined_<name>``).

Pass names changed over versions ("Diffuse Direct" in 5.0, "DiffDir" before 4.0): both are accepted. Nothing
here imports bpy; `batch.render` enables the passes.
"""

from __future__ import annotations

from typing import TYPE_CHECKING

from ..errors import BatchError

if TYPE_CHECKING:  # numpy is imported where the layers are made: `batch.jobs.options` imports this module light
    import numpy as np

#: The components of Combined, in the order the report lists them.
COMPONENTS = ("diffuse", "glossy", "transmission", "volume", "emission", "environment")
#: What ``--lobes`` accepts (``all`` is every one of them).
LOBES = (*COMPONENTS, "lightgroups")

#: Each component's passes: (the 5.0 name, the name before 4.0). A colour-split lobe: direct, indirect, colour.
_SPLIT = {
    "diffuse": (("Diffuse Direct", "DiffDir"), ("Diffuse Indirect", "DiffInd"), ("Diffuse Color", "DiffCol")),
    "glossy": (("Glossy Direct", "GlossDir"), ("Glossy Indirect", "GlossInd"), ("Glossy Color", "GlossCol")),
    "transmission": (("Transmission Direct", "TransDir"), ("Transmission Indirect", "TransInd"),
                     ("Transmission Color", "TransCol")),
}  # fmt: skip
_ADDITIVE = {
    "volume": (("Volume Direct", "VolumeDir"), ("Volume Indirect", "VolumeInd")),
    "emission": (("Emission", "Emit"),),
    "environment": (("Environment", "Env"),),
}

#: The view-layer properties that enable each component's passes (Volume's are Cycles' own, on ``layer.cycles``).
PASS_PROPERTIES = {
    "diffuse": ("use_pass_diffuse_direct", "use_pass_diffuse_indirect", "use_pass_diffuse_color"),
    "glossy": ("use_pass_glossy_direct", "use_pass_glossy_indirect", "use_pass_glossy_color"),
    "transmission": ("use_pass_transmission_direct", "use_pass_transmission_indirect",
                     "use_pass_transmission_color"),
    "volume": ("cycles.use_pass_volume_direct", "cycles.use_pass_volume_indirect"),
    "emission": ("use_pass_emit",),
    "environment": ("use_pass_environment",),
}  # fmt: skip

LIGHTGROUP_PREFIX = "lightgroup:"


def parse_lobes(text: str) -> tuple[str, ...]:
    """``all`` or a comma-separated list of `LOBES`, in `LOBES` order."""
    names = [n.strip() for n in text.split(",") if n.strip()]
    if names == ["all"]:
        return LOBES
    unknown = [n for n in names if n not in LOBES]
    if not names or unknown:
        raise BatchError(f"--lobes takes 'all' or some of {','.join(LOBES)}, got {text!r}")
    return tuple(n for n in LOBES if n in names)


def layers_from_channels(channels: dict[str, np.ndarray], lobes) -> dict[str, np.ndarray]:
    """The image and every requested layer (H×W×3 float32) from the channels of a multilayer EXR of one pass (one
    view layer): ``combined``, the components, and ``lightgroup:<name>`` for each light group."""
    combined = sorted(key for key in channels if key.endswith(".Combined.R"))
    if not combined:
        raise BatchError(f"the pass has no Combined layer (its channels: {', '.join(sorted(channels)[:12])})")
    prefix = combined[0].removesuffix("Combined.R")
    names = {key.removeprefix(prefix).rpartition(".")[0] for key in channels if key.startswith(prefix)}

    import numpy as np

    def rgb(*alternatives: str) -> np.ndarray:
        for name in alternatives:
            if name in names:
                return np.stack([channels[f"{prefix}{name}.{c}"] for c in "RGB"], axis=-1)
        raise BatchError(f"the pass has no {alternatives[0]!r} layer (its layers: {', '.join(sorted(names))})")

    out = {"combined": rgb("Combined")}
    for lobe in lobes:
        if lobe in _SPLIT:
            direct, indirect, colour = (rgb(*n) for n in _SPLIT[lobe])
            out[lobe] = (direct + indirect) * colour
        elif lobe in _ADDITIVE:
            out[lobe] = sum(rgb(*n) for n in _ADDITIVE[lobe])
    if "lightgroups" in lobes:
        for name in sorted(n for n in names if n.startswith("Combined_")):
            out[LIGHTGROUP_PREFIX + name.removeprefix("Combined_")] = rgb(name)
    return out
