"""One rule for a pass with NaN or inf pixels, wherever passes come from (renders, EXR files)."""

from __future__ import annotations

import numpy as np

from .._siblings import welch_core as wc
from .options import ON_NAN


def add_pass(stats: wc.TileStats, image: np.ndarray, seed: int, on_nan: str, warn) -> bool:
    """Add `image` to `stats` under the `on_nan` policy; return False if it was skipped (after calling `warn`)."""
    if on_nan not in ON_NAN:
        raise wc.WelchInputError(f"`on_nan` must be one of {ON_NAN}, got {on_nan!r}")
    if on_nan == "skip" and not np.isfinite(image[..., : stats.channels]).all():
        bad = int((~np.isfinite(image[..., : stats.channels])).sum())
        warn(f"pass with seed {seed} has {bad} non-finite pixel values: skipped")
        return False
    stats.add_pass(image, seed, allow_nonfinite=on_nan == "keep")
    return True


def add_layered_pass(stats: wc.TileStats, layers: dict[str, wc.TileStats], images: dict[str, np.ndarray], seed: int,
                     on_nan: str, warn) -> bool:  # fmt: skip
    """`add_pass` for a pass with layers (``images``: ``combined`` and one image per layer of `layers`): all or
    none of them are added, so the image and its layers always hold the same passes."""
    if on_nan == "skip":
        bad = sorted(name for name, image in images.items() if not np.isfinite(image[..., : stats.channels]).all())
        if bad:
            warn(f"pass with seed {seed} has non-finite pixel values in {', '.join(bad)}: skipped")
            return False
    for name, layer in layers.items():  # checked before the image is added: a refused layer adds nothing
        if not np.isfinite(images[name][..., : layer.channels]).all() and on_nan == "stop":
            raise wc.WelchInputError(f"pass with seed {seed} has non-finite pixel values in layer {name!r}")
    if not add_pass(stats, images["combined"], seed, on_nan, warn):
        return False
    for name, layer in layers.items():
        layer.add_pass(images[name], seed, allow_nonfinite=on_nan == "keep")
    return True


def channel_layers(channels: dict[str, np.ndarray], names, source: str) -> dict[str, np.ndarray]:
    """The layers `names` of a multilayer EXR's channels: each name's ``<name>.R/G/B`` (under any view-layer
    prefix, as ``ViewLayer.<name>.R``), as H×W×3 float32."""
    out = {}
    for name in names:
        found = sorted(k.removesuffix(".R") for k in channels if k == f"{name}.R" or k.endswith(f".{name}.R"))
        if not found or not all(f"{found[0]}.{c}" in channels for c in "GB"):
            layers = sorted({k.rpartition(".")[0] for k in channels if "." in k})
            raise wc.WelchInputError(f"{source} has no layer {name!r} with R, G, B (its layers: {', '.join(layers)})")
        out[name] = np.stack([channels[f"{found[0]}.{c}"] for c in "RGB"], axis=-1)
    return out
