"""Stand-ins for the pass renderer (batch.blender.render.PassRenderer) where Cycles can't be made to do it."""

import numpy as np


class NanEverySecondPass:
    """Cycles can't be made to return NaN: odd seeds give a pass with one NaN pixel value, even seeds a clean one."""

    def render(self, seed):
        image = np.full((32, 32, 3), 0.5, np.float32) + np.random.default_rng(seed).random((32, 32, 3), np.float32)
        if seed % 2:
            image[1, 2, 0] = np.nan
        return image
