"""A fingerprint of the hair a scene makes: sha1 of the guide and ghost positions over 20 poses
of a moving, turning head, for the default scene and its PBD, XPBD and once-per-pose variants;
with ``--more`` also the paper and turn trackers, the body's bust (the long-hair preset), a dt
of 1/30 s (split substeps) and crowds of three people (:class:`~hair_tracking.people.crowd.Crowd`:
FTL's batched path, with a fast turn that splits substeps, and PBD's and the bust's one call a
person).

Run it before and after a change that must not change behaviour (a refactor, a move): the
hashes must be identical.  A change that may move the hair by rounding only: ``--save DIR``
before it keeps every variant's positions, ``--against DIR`` after it prints each variant's
largest node difference [m] from them.

    python scripts/hash_steps.py [--more] [--save DIR | --against DIR]
"""
import argparse
import hashlib
import os
import sys

sys.path.insert(0, os.path.dirname(os.path.dirname(os.path.abspath(__file__))))

from hair_tracking.executable import use_numba_cache  # noqa: E402
use_numba_cache()      # before numba loads: the cache make install fills
import numpy as np  # noqa: E402

from hair_tracking.core.scene import Scene  # noqa: E402
from hair_tracking.people.crowd import Crowd  # noqa: E402
from hair_tracking.resources import config_path  # noqa: E402
from hair_tracking.simulator import HairSimulator  # noqa: E402

VARIANTS = {'default': {}, 'pbd': {'solver__type': 'pbd'}, 'xpbd': {'solver__type': 'xpbd'},
            'once': {'tracking__every_substep': False}, 'blend': {'tracking__mode': 'blend'}}
#: ``--more``: further single-head variants of the default scene ...
MORE = {'paper': {'tracking__mode': 'paper'},
        'paper_once': {'tracking__mode': 'paper', 'tracking__every_substep': False},
        'paper_pbd': {'tracking__mode': 'paper', 'solver__type': 'pbd'},
        'turn': {'tracking__mode': 'turn'}, 'bust': {'body__bust': True},
        'xpbd_bust': {'body__bust': True, 'solver__type': 'xpbd'},
        'no_collider': {'collider__shape': 'none'}, 'dt_1/30': {'solver__dt': 1 / 30}}
#: ... and crowds of three people of a small groom: (changes, a fast turn that splits).
CROWD_GROOM = {'groom__guides': 16, 'groom__ghosts_per_guide': 4, 'solver__settle_time': 0.1}
CROWDS = {'crowd_ftl': ({}, False), 'crowd_ftl_fast': ({}, True),
          'crowd_paper_once': ({'tracking__mode': 'paper', 'tracking__every_substep': False},
                               True),
          'crowd_no_collider': ({'collider__shape': 'none'}, True),
          'crowd_pbd': ({'solver__type': 'pbd'}, True), 'crowd_bust': ({'body__bust': True}, True)}


def head_pose(k: int, i: int = 0, fast: bool = False):
    """Head ``i``'s pose ``k``: ``(t_ns, position, quaternion)``, nodding and swaying (``fast``:
    a turn of 1.2 rad in one pose at pose 5)."""
    a = 0.3 * np.sin(k * 0.4 + i) + (1.2 if fast and k >= 5 else 0.0)
    return 1_000_000_000 + k * 16_666_667, [0.5 * i + 0.02 * np.sin(k * 0.3), 0.0, 0.0], \
        [0.0, 0.0, np.sin(a / 2), np.cos(a / 2)]


class Print:
    """The sha1 of the frames it is given, and their positions (``points``)."""

    def __init__(self):
        self.sha = hashlib.sha1()
        self.points = []

    def update(self, frame) -> None:
        for x in (frame.guides, frame.ghosts):
            if x is not None:
                self.sha.update(x.tobytes())
                self.points.append(np.asarray(x, dtype=np.float64).reshape(-1))

    def hexdigest(self) -> str:
        return self.sha.hexdigest()


def _update(h, frame) -> None:
    h.update(frame)


def fingerprint(scene: Scene, poses: int = 21) -> Print:
    sim = HairSimulator(scene)
    h = Print()
    for k in range(poses):
        t, p, q = head_pose(k)
        sim.push_pose(t, p, q)
        sim.advance_to(t)
        _update(h, sim.frame())
    return h


def crowd_fingerprint(scene: Scene, fast: bool, people: int = 3, poses: int = 21) -> Print:
    """:func:`fingerprint` of a crowd of ``people`` side by side, each nodding its own way."""
    crowd = Crowd(scene, people + 1)
    h = Print()
    for k in range(poses):
        for i in range(people):
            t, p, q = head_pose(k, i, fast)
            if k == 0:
                crowd.add(str(i), t, p, q)
            else:
                crowd.push_pose(str(i), t, p, q)
        crowd.advance_to(t)
        for i in range(people):
            _update(h, crowd.people[str(i)].frame())
    return h


def report(name: str, h: Print, args) -> None:
    """Print the variant's fingerprint; keep its positions (``--save``) or compare them with
    the kept ones (``--against``)."""
    points = np.concatenate(h.points)
    line = f'{name} {h.hexdigest()}'
    key = name.replace('/', '_')
    if args.save:
        np.save(os.path.join(args.save, key + '.npy'), points)
    if args.against:
        kept = np.load(os.path.join(args.against, key + '.npy'))
        line += f'  max |difference| {np.max(np.abs(points - kept)):.3g} m'
    print(line, flush=True)


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__.split('\n\n')[0])
    ap.add_argument('--more', action='store_true',
                    help='also the trackers, the bust, long substeps and crowds')
    ap.add_argument('--save', metavar='DIR', help="keep every variant's positions in DIR")
    ap.add_argument('--against', metavar='DIR',
                    help='print the largest node difference from the positions kept in DIR')
    args = ap.parse_args()
    if args.save:
        os.makedirs(args.save, exist_ok=True)
    for name, changes in VARIANTS.items():
        report(name, fingerprint(Scene().with_changes(**changes) if changes else Scene()),
               args)
    if not args.more:
        return 0
    for name, changes in MORE.items():
        report(name, fingerprint(Scene().with_changes(**changes)), args)
    report('long_hair', fingerprint(Scene.from_yaml(config_path('scene_long_hair.yaml'))),
           args)
    for name, (changes, fast) in CROWDS.items():
        report(name, crowd_fingerprint(Scene().with_changes(**CROWD_GROOM, **changes), fast),
               args)
    return 0


if __name__ == '__main__':
    sys.exit(main())
