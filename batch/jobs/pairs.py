"""Each pixel's difference per seed for a paired check: the pixel-variance test of paired runs needs the moments of
test - reference for every pixel over the seeds (`welch_core.pixels`), which neither side's statistics can hold,
as each side renders in its own process. So each side also writes every pass's image into a folder of the check
(`save_pass_image`), and the check folds the two images of each seed into the moments of their difference before
a look (`PixelPairs`) and deletes them: a few images on disk at a time, the moments in ``pairs.npz``.

Saved before the images are deleted, so a crash in between leaves images whose seeds the moments already hold
(deleted at the next look). A seed whose image a side lost (a check started before the images were kept, a
side on Dask workers) ends the pairs: the looks test the tile sums from then on, and say why.

numpy only: `save_pass_image` runs inside Blender.
"""

from __future__ import annotations

import os
import zipfile
from pathlib import Path

import numpy as np

from .._siblings import welch_core as wc

#: The folder of a side's pass images in a check's folder, and the file of the moments.
FOLDER, FILE = "pairs", "pairs.npz"


def save_pass_image(folder: str, seed: int, image: np.ndarray) -> None:
    """Write a pass's RGB image as ``<folder>/<seed>.npy`` (float32), atomically."""
    os.makedirs(folder, exist_ok=True)
    rgb = np.ascontiguousarray(np.asarray(image)[..., :3], dtype=np.float32)
    wc.formats.atomic_write(os.path.join(folder, f"{seed}.npy"), lambda f: np.save(f, rgb, allow_pickle=False))


class PixelPairs:
    """The moments of each pixel's difference test - reference over the seeds folded so far, in a check's folder
    `out`, from the pass images its two sides write into ``<out>/pairs/<side>/``."""

    def __init__(self, out: str | os.PathLike):
        self.out = Path(out)
        self.path = self.out / FILE
        self.moments: wc.PixelMoments | None = None
        self.seeds: list[int] = []
        self.broken = False  # a seed's image was missing: the pairs can no longer match the sides
        if self.path.exists():
            self._load()

    @staticmethod
    def folder(out: str | os.PathLike, side: str) -> str:
        return str(Path(out) / FOLDER / side)

    @staticmethod
    def clear(out: str | os.PathLike) -> None:
        """Remove the pairs of an earlier check in `out` (a new check in the same folder)."""
        Path(out, FILE).unlink(missing_ok=True)
        for side in ("reference", "test"):
            folder = Path(PixelPairs.folder(out, side))
            for image in folder.glob("*.npy") if folder.is_dir() else ():
                image.unlink(missing_ok=True)

    def _load(self) -> None:
        try:
            with np.load(self.path, allow_pickle=False) as data:
                self.seeds = [int(s) for s in data["seeds"]]
                self.broken = bool(data["broken"])
                if self.seeds:
                    self.moments = wc.PixelMoments.of(data["mean"], data["m2"], len(self.seeds))
        except (OSError, KeyError, ValueError, zipfile.BadZipFile, wc.WelchInputError):
            self.moments, self.seeds, self.broken = None, [], True  # unreadable: tile sums from here on

    def _save(self) -> None:
        arrays = {"seeds": np.asarray(self.seeds, dtype=np.int64), "broken": np.asarray(self.broken)}
        if self.moments is not None:
            arrays |= {"mean": self.moments.mean, "m2": self.moments.m2}
        wc.formats.atomic_write(self.path, lambda f: np.savez(f, **arrays))

    def at(self, seeds) -> wc.PixelMoments | None:
        """The moments over exactly `seeds` (a look's, in the order rendered), folding in the images of the seeds
        not yet folded; None where the pairs can't give them."""
        seeds = [int(s) for s in seeds]
        if self.broken or seeds[: len(self.seeds)] != self.seeds:
            return None
        images = {side: Path(self.folder(self.out, side)) for side in ("reference", "test")}
        new = seeds[len(self.seeds) :]
        for seed in new:
            files = [images[side] / f"{seed}.npy" for side in ("reference", "test")]
            try:
                ref, test = (np.load(f, allow_pickle=False) for f in files)
            except (OSError, ValueError):
                self.broken = True
                break
            if self.moments is None:
                self.moments = wc.PixelMoments(*ref.shape)
            self.moments.add(test.astype(np.float64) - ref)
            self.seeds.append(seed)
        if new:
            self._save()
            for seed in self.seeds:  # folded: no longer needed (also those a crash left after an earlier save)
                for folder in images.values():
                    (folder / f"{seed}.npy").unlink(missing_ok=True)
        return None if self.broken else self.moments
