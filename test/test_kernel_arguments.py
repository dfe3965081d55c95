"""The kernels' structured arguments: the tuples the solvers pass hold the named fields."""
import numpy as np

from hair_tracking.guides import ftl

from hair_tracking.guides import pbd_constraints

from hair_tracking.core.model import StrandSet
from hair_tracking.core.scene import Scene
from hair_tracking.ghosts import kernels as tracking_kernels
from hair_tracking.ghosts.tracker import GhostTracker
from hair_tracking.guides.solver import GuideSolver


def hanging(count, nodes=6):
    rest = np.zeros((count, nodes, 3))
    rest[:, :, 0] = np.arange(count)[:, None] * 0.01
    rest[:, :, 2] = -0.02 * np.arange(nodes)
    return rest


def test_solver_models_hold_the_named_fields_in_order():
    for kind, fields in (('ftl', ftl.FtlModel._fields), ('pbd', pbd_constraints.PbdModel._fields),
                         ('xpbd', pbd_constraints.XpbdModel._fields)):
        strands = StrandSet.from_rest(hanging(3))
        solver = GuideSolver(strands, Scene().with_changes(solver__type=kind))
        if kind == 'xpbd':
            solver._xpbd_factors(1.0 / 240.0)
        model = solver._model
        assert type(model) is tuple and len(model) == len(fields), kind
        assert model[fields.index('rest')] is strands.rest
        assert model[fields.index('inv_mass')] is strands.inv_mass


def test_ghost_model_holds_the_named_fields_in_order():
    guides = StrandSet.from_rest(hanging(2))
    ghosts = StrandSet.from_rest(hanging(6) + np.array([0.001, 0.0, 0.0]))
    tracker = GhostTracker(ghosts, guides, Scene())
    fields = tracking_kernels.GhostModel._fields
    assert type(tracker._model) is tuple and len(tracker._model) == len(fields)
    for name, attr in (('rest', ghosts.rest), ('order', tracker.order),
                       ('group_start', tracker.group_start), ('tan_rest', tracker._tan_rest),
                       ('var_target', tracker._var_target)):
        assert tracker._model[fields.index(name)] is attr, name
    work = tracking_kernels.TrackWork._fields
    assert len(tracker._work) == len(work)
    assert tracker._work[work.index('clamped')] is tracker._clamped
