"""The kernels' structured arguments: the tuples the solvers pass hold the named fields, and no
numba function of the simulation (the default path: FTL guides, ellipsoid collider, blend
tracker with its guides chosen among the strands, point records; the turn and the paper's
trackers; the groom files' guide choice) takes more than ten arguments."""
import importlib
import inspect
import pkgutil
import types

import numba
import numpy as np
import pytest

from hair_tracking.core import metrics, point_records
from hair_tracking.core.model import HeadPose, StrandSet
from hair_tracking.core.scene import Scene
from hair_tracking.ghosts import blend, stateless, turn
from hair_tracking.ghosts import kernels as tracking_kernels
from hair_tracking.ghosts.interface import TrackStep
from hair_tracking.ghosts.tracker import GhostTracker
from hair_tracking.grooms import guides as groom_guides
from hair_tracking.colliders import head as collision
from hair_tracking.guides import ftl, integrate, pbd_constraints
from hair_tracking.guides.solver import make_solver

#: The modules whose compiled functions the default scene runs (FTL guides with the ellipsoid
#: collider, the blend tracker and its guides chosen among the strands by farthest-point
#: sampling, the point records of the cloud, the stretch check)
DEFAULT_PATH = (integrate, ftl, pbd_constraints, collision, stateless, blend, groom_guides,
                point_records, metrics)
#: ... and the turn tracker's
TURN = (turn,)
MOST_ARGUMENTS = 10


def hanging(count, nodes=6):
    rest = np.zeros((count, nodes, 3))
    rest[:, :, 0] = np.arange(count)[:, None] * 0.01
    rest[:, :, 2] = -0.02 * np.arange(nodes)
    return rest


def dispatchers(module):
    """The numba functions ``module`` defines: ``{name: dispatcher}``."""
    return {name: obj for name, obj in vars(module).items()
            if isinstance(obj, numba.core.dispatcher.Dispatcher)
            and obj.py_func.__module__ == module.__name__}


def simulation_modules():
    """Every module of the layers that simulate (core, grooms, guides, ghosts) and the head's
    row of the colliders (the contact model's one-node functions take a node and a shape by
    their numbers)."""
    import hair_tracking.core
    import hair_tracking.ghosts
    import hair_tracking.grooms
    import hair_tracking.guides
    found = [collision]
    for package in (hair_tracking.core, hair_tracking.grooms, hair_tracking.guides,
                    hair_tracking.ghosts):
        for info in pkgutil.iter_modules(package.__path__, package.__name__ + '.'):
            found.append(importlib.import_module(info.name))
    return found


def test_the_default_path_and_the_turn_tracker_are_checked():
    names = {m.__name__ for m in simulation_modules()}
    assert {m.__name__ for m in DEFAULT_PATH + TURN} <= names


@pytest.mark.parametrize('module', simulation_modules(), ids=lambda m: m.__name__)
def test_no_numba_function_takes_more_than_ten_arguments(module):
    found = dispatchers(module)
    if module in DEFAULT_PATH + TURN:
        assert found, module.__name__
    over = {name: len(inspect.signature(d.py_func).parameters) for name, d in found.items()
            if len(inspect.signature(d.py_func).parameters) > MOST_ARGUMENTS}
    assert not over, f'{module.__name__}: {over}'


def test_the_argument_count_check_can_fail():
    @numba.njit
    def eleven(a, b, c, d, e, f, g, h, i, j, k):
        return a
    assert len(inspect.signature(eleven.py_func).parameters) > MOST_ARGUMENTS
    assert 'eleven' in dispatchers(types.SimpleNamespace(__name__=__name__, eleven=eleven))


def test_solver_models_hold_the_named_fields_in_order():
    head = HeadPose(np.zeros(3), np.array([0.0, 0.0, 0.0, 1.0]), np.eye(3))
    for kind, fields in (('ftl', ftl.FtlModel._fields), ('pbd', pbd_constraints.PbdModel._fields),
                         ('xpbd', pbd_constraints.XpbdModel._fields)):
        strands = StrandSet.from_rest(hanging(3))
        solver = make_solver(strands, Scene().with_changes(solver__type=kind))
        solver.step(1.0 / 240.0, head, head)          # XPBD builds its model for the dt
        model = solver.model
        assert type(model) is tuple and len(model) == len(fields), kind
        assert model[fields.index('rest')] is strands.rest
        assert model[fields.index('inv_mass')] is strands.inv_mass


def test_collider_model_holds_the_named_fields_in_order():
    c = collision.head_collider(Scene().collider)
    fields = collision.ColliderModel._fields
    assert type(c.model) is tuple and len(c.model) == len(fields)
    assert c.model[fields.index('radii')] is c.radii
    assert c.model[fields.index('margin')] == c.margin


@pytest.mark.parametrize('mode, model, params', [
    ('blend', blend.BlendModel, blend.BlendParams), ('turn', turn.TurnModel, turn.TurnParams)])
def test_stateless_models_hold_the_named_fields_in_order(mode, model, params):
    from hair_tracking.simulator import HairSimulator
    sim = HairSimulator(Scene().with_changes(groom__guides=4, groom__ghosts_per_guide=3,
                                             tracking__mode=mode, solver__settle_time=0.0))
    tr = sim.ghost_tracker
    assert type(tr.model) is tuple and len(tr.model) == len(model._fields)
    assert type(tr.params) is tuple and len(tr.params) == len(params._fields)
    named = params(*tr.params)
    assert named.center is tr.center and named.axes is tr.axes and named.collide == tr.collide


def test_ghost_model_holds_the_named_fields_in_order():
    guides = StrandSet.from_rest(hanging(2))
    ghosts = StrandSet.from_rest(hanging(6) + np.array([0.001, 0.0, 0.0]))
    tracker = GhostTracker(ghosts, guides, Scene().with_changes(tracking__tip_weight=5.0,
                                                                tracking__max_weight=0.5))
    fields = tracking_kernels.GhostModel._fields
    assert type(tracker.model) is tuple and len(tracker.model) == len(fields)
    for name, attr in (('rest', ghosts.rest), ('order', tracker.order),
                       ('group_start', tracker.group_start)):
        assert tracker.model[fields.index(name)] is attr, name
    model = tracking_kernels.GhostModel(*tracker.model)
    np.testing.assert_allclose(np.linalg.norm(model.tan_rest, axis=2), 1.0)
    work = tracking_kernels.TrackWork._fields
    assert len(tracker.work) == len(work)
    head = HeadPose(np.array([0.1, 0.0, 0.0]), np.array([0.0, 0.0, 0.0, 1.0]), np.eye(3))
    old = guides.x.copy()
    guides.x[...] = head.to_world(guides.rest)
    tracker.step(TrackStep(1.0 / 240.0, 1, old, guides.x, head))
    clamped = tracker.work[work.index('clamped')]
    assert tracker.stats['clamped'] == clamped.sum() > 0     # the counts the kernel wrote
