"""Each pixel's difference per seed for a paired check: the pixel-variance test of paired runs needs the moments of
test - reference for every pixel over the seeds (`welch_core.pixels`), which neither side's statistics can hold,
as each side renders in its own process. So each side also keeps every pass's image in a folder of the check
(`save_pass_image`), and the check folds the two images of each seed into the moments of their difference before
a look (`PixelPairs`) and deletes them: a few images on disk at a time, the moments in ``pairs.npz``.

A pass's image is the EXR file its renderer wrote and the side read (Blender's saved pass, a command's ``{out}``),
renamed into the folder: no second write, one more read (the check's). The renderer writes it in that folder where
it can (`batch.blender.render.PassRenderer`), so the rename stays on one file system; otherwise it is copied once.
The files are not fsynced: an image a crash lost is a missing one (below), as the moments are saved first.

Saved before the images are deleted, so a crash in between leaves images whose seeds the moments already hold
(deleted at the next look). A seed whose image a side lost (a check started before the images were kept, a
side on Dask workers) ends the pairs: the looks test the tile sums from then on, and say why.

numpy only: `save_pass_image` runs inside Blender.
"""

from __future__ import annotations

import errno
import os
import secrets
import shutil
import zipfile
from pathlib import Path

import numpy as np

from .._siblings import welch_core as wc

#: The folder of a side's pass images in a check's folder, and the file of the moments.
FOLDER, FILE = "pairs", "pairs.npz"


def save_pass_image(folder: str, seed: int, image: np.ndarray, source: str | None = None) -> None:
    """Keep a pass's image as ``<folder>/<seed>.exr``: the pass's own EXR file `source` (its colour is `image`),
    renamed, or copied where it lies on another file system; without one, `image` written as an EXR. Never a
    partial file under that name (a temporary one, renamed)."""
    os.makedirs(folder, exist_ok=True)
    path = os.path.join(folder, f"{seed}.exr")
    if source is not None:
        try:
            os.replace(source, path)
            return
        except OSError as exc:
            if exc.errno != errno.EXDEV:
                raise
    tmp = os.path.join(folder, f".welch-{secrets.token_hex(6)}.tmp")
    try:
        if source is not None:
            shutil.copyfile(source, tmp)
        else:
            with open(tmp, "wb") as f:
                f.write(wc.exr.exr_bytes(np.asarray(image)[..., :3]))
        os.replace(tmp, path)
    except BaseException:
        Path(tmp).unlink(missing_ok=True)
        raise


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
            for image in [*folder.glob("*.exr"), *folder.glob("*.npy")] if folder.is_dir() else ():
                image.unlink(missing_ok=True)  # (.npy: the images of earlier versions of this tool)

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
        difference = None
        for seed in new:
            files = [images[side] / f"{seed}.exr" for side in ("reference", "test")]
            try:
                ref, test = (wc.read_exr(f) for f in files)
            except wc.WelchInputError:
                self.broken = True
                break
            if self.moments is None:
                self.moments = wc.PixelMoments(*ref.shape)
            if difference is None:
                difference = np.empty(ref.shape)
            np.subtract(test, ref, out=difference, dtype=np.float64)
            self.moments.add(difference)
            self.seeds.append(seed)
        if new:
            self._save()
            for seed in self.seeds:  # folded: no longer needed (also those a crash left after an earlier save)
                for folder in images.values():
                    (folder / f"{seed}.exr").unlink(missing_ok=True)
        return None if self.broken else self.moments
