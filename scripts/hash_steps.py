"""A fingerprint of the hair a scene makes: sha1 of the guide and ghost positions over 20 poses
of a moving, turning head, for the default scene and its PBD, XPBD and once-per-pose variants.

Run it before and after a change that must not change behaviour (a refactor, a move): the
hashes must be identical.

    python scripts/hash_steps.py
"""
import hashlib
import os
import sys

sys.path.insert(0, os.path.dirname(os.path.dirname(os.path.abspath(__file__))))

from hair_tracking.executable import use_numba_cache  # noqa: E402
use_numba_cache()      # before numba loads: the cache make install fills
import numpy as np  # noqa: E402

from hair_tracking.core.scene import Scene  # noqa: E402
from hair_tracking.simulator import HairSimulator  # noqa: E402

VARIANTS = {'default': {}, 'pbd': {'solver__type': 'pbd'}, 'xpbd': {'solver__type': 'xpbd'},
            'once': {'tracking__every_substep': False}, 'blend': {'tracking__mode': 'blend'}}


def fingerprint(scene: Scene, poses: int = 21) -> str:
    sim = HairSimulator(scene)
    h = hashlib.sha1()
    t0 = 1_000_000_000
    for k in range(poses):
        a = 0.3 * np.sin(k * 0.4)
        t = t0 + k * 16_666_667
        q = [0.0, 0.0, np.sin(a / 2), np.cos(a / 2)]
        sim.push_pose(t, [0.02 * np.sin(k * 0.3), 0.0, 0.0], q)
        sim.advance_to(t)
        f = sim.frame()
        h.update(f.guides.tobytes())
        if f.ghosts is not None:
            h.update(f.ghosts.tobytes())
    return h.hexdigest()


def main() -> int:
    for name, changes in VARIANTS.items():
        print(name, fingerprint(Scene().with_changes(**changes) if changes else Scene()),
              flush=True)
    return 0


if __name__ == '__main__':
    sys.exit(main())
