"""Multilayer passes of another renderer (layers 'diffuse' and 'glossy'), written here and ingested with --layers."""

import numpy as np

from batch import cli
from welch_core.exr import write_exr_channels


def write_layered_passes(folder, seeds, glossy_scale=1.0, drop=None):
    """Multilayer EXRs of another renderer: layers 'diffuse' and 'glossy' and their sum as RGB."""
    paths = []
    for seed in seeds:
        rng = np.random.default_rng(seed)
        diffuse = rng.exponential(0.4, (32, 48, 3)).astype(np.float32)
        glossy = (rng.exponential(0.2, (32, 48, 3)) * glossy_scale).astype(np.float32)
        channels = {}
        for name, image in (("diffuse", diffuse), ("glossy", glossy), ("", diffuse + glossy)):
            for k, ch in enumerate("RGB"):
                channels[f"{name}.{ch}" if name else ch] = image[..., k]
        if drop:
            channels = {k: v for k, v in channels.items() if not k.startswith(drop)}
        path = folder / f"pass_{seed:03d}.exr"
        write_exr_channels(path, channels)
        paths.append(str(path))
    return paths


def ingest_layers(tmp_path, name, seeds, glossy_scale=1.0, layers="diffuse,glossy"):
    folder = tmp_path / name
    folder.mkdir()
    paths = write_layered_passes(folder, seeds, glossy_scale)
    out = str(tmp_path / f"{name}.npz")
    args = ["ingest", *paths, "--spp", "1", "--tile", "8", "--layers", layers, "--out", out]
    assert cli.main([*args, "--seeds", ",".join(map(str, seeds))]) == 0
    return out
