"""Parameters of the running node through a parameter client: what ``ros2 param`` does.

``list``, ``describe``, ``get``, ``set`` and ``load`` go through the node's parameter services
over DDS (rclpy's AsyncParameterClient, the same services the ros2 CLI calls).  Domain ids
35-49 (test_node.py uses 20-34).
"""
import itertools

import numba
import numpy as np
import pytest
from rcl_interfaces.msg import ParameterType
import rclpy
from rclpy.parameter import Parameter
from rclpy.parameter_client import AsyncParameterClient
import yaml

from hair_tracking.core import param_table as P
from hair_tracking.core.params import ParamError
from hair_tracking.core.scene import Scene
from msg_adapters.pointcloud import pointcloud2_to_strands
from msg_adapters.pose import pose_stamped_msg
from visualization_msgs.msg import Marker

from test_node import Harness, roots_in_head, yaw_quat

_DOMAINS = itertools.cycle(range(35, 50))


@pytest.fixture
def rig():
    h = Harness(domain_id=next(_DOMAINS))
    h.client = AsyncParameterClient(h.probe, 'hair_sim')
    assert h.client.wait_for_services(timeout_sec=10.0)
    yield h
    h.close()


def call(h, future, what):
    h.spin_until(future.done, what=what)
    return future.result()


def set_(h, **values):
    """Like ``ros2 param set``: one parameter per request; returns the results."""
    prms = [Parameter(k.replace('__', '.'), value=v) for k, v in values.items()]
    return call(h, h.client.set_parameters(prms), 'set_parameters').results


def pose_loop(h, ks, x=0.0):
    """Publish poses at grid steps ``ks`` (on the dt grid) and return the last stamp."""
    pub = h.pose_publisher()
    dt_ns = h.node.sim.dt_ns
    times = [10**9 + 4 * k * dt_ns for k in ks]
    for t in times:
        h.send(pub, pose_stamped_msg(t, [x, 0.0, 0.0], yaw_quat(0.0), 'world'))
    return times[-1]


def first_markers_with(h, marker_type):
    """Spin until a MarkerArray holding ``marker_type`` markers arrives; returns the first."""
    def find():
        return next((a for a in h.markers if any(m.type == marker_type and
                                                 m.action == Marker.ADD for m in a.markers)),
                    None)
    h.spin_until(lambda: find() is not None, what=f'markers of type {marker_type}')
    return find()


def test_list_and_describe_show_every_parameter_with_its_range(rig):
    res = call(rig, rig.client.list_parameters([], 0), 'list_parameters')
    names = set(res.result.names)
    assert set(p.name for p in P.table()) <= names
    assert 'use_sim_time' in names
    wanted = ['solver.stiffness', 'groom.guides', 'warmup', 'solver.type', 'gravity',
              'publish_rate_hz']
    res = call(rig, rig.client.describe_parameters(wanted), 'describe_parameters')
    d = {x.name: x for x in res.descriptors}
    assert d['solver.stiffness'].type == ParameterType.PARAMETER_DOUBLE
    assert d['solver.stiffness'].additional_constraints == '(0.0, 1.0]'
    assert d['groom.guides'].additional_constraints == '[1, 100000]'
    # rclpy ranges (rqt sliders), bounds included; the open bound is refused by the node
    r = d['groom.guides'].integer_range[0]
    assert (r.from_value, r.to_value, r.step) == (1, 100000, 1)
    r = d['solver.stiffness'].floating_point_range[0]
    assert (r.from_value, r.to_value, r.step) == (0.0, 1.0, 0.0)
    assert not d['gravity'].floating_point_range
    assert 'rebuilds the hair' in d['groom.guides'].description
    assert d['warmup'].read_only and not d['groom.guides'].read_only
    assert d['solver.type'].additional_constraints == 'one of: ftl, pbd, xpbd'
    assert d['gravity'].type == ParameterType.PARAMETER_DOUBLE_ARRAY
    assert d['publish_rate_hz'].description.endswith('[Hz]')


def test_get_returns_the_values_with_their_types(rig):
    table = P.by_name()
    names = [p.name for p in P.table()]
    res = call(rig, rig.client.get_parameters(names), 'get_parameters')
    kinds = {ParameterType.PARAMETER_BOOL: 'bool', ParameterType.PARAMETER_INTEGER: 'int',
             ParameterType.PARAMETER_DOUBLE: 'double', ParameterType.PARAMETER_STRING: 'string',
             ParameterType.PARAMETER_DOUBLE_ARRAY: 'double_array'}
    for name, value in zip(names, res.values):
        assert kinds[value.type] == table[name].kind, name
    got = dict(zip(names, res.values))
    assert got['groom.guides'].integer_value == 4                   # the harness' override
    assert tuple(got['gravity'].double_array_value) == (0.0, 0.0, -9.81)


def test_valid_change_takes_effect_on_the_next_frame(rig):
    rig.listen()
    t = pose_loop(rig, [0])
    rig.markers_at(t)
    res = set_(rig, marker_style='line_strips', marker_width=0.005)
    assert all(r.successful for r in res)
    arr = first_markers_with(rig, Marker.LINE_STRIP)
    assert arr.markers[0].action == Marker.DELETEALL                 # style changed: clear
    strips = [m for m in arr.markers if m.action == Marker.ADD]
    assert len(strips) == 12 and {m.type for m in strips} == {Marker.LINE_STRIP}
    assert {m.scale.x for m in strips} == {0.005}
    assert [m.id for m in strips] == list(range(12))
    later = rig.markers[rig.markers.index(arr) + 1:]
    assert all(m.type == Marker.LINE_STRIP for a in later for m in a.markers
               if m.action == Marker.ADD)
    # a scene parameter reaches the simulator at the next step
    assert set_(rig, gravity=[0.0, 0.0, -3.0])[0].successful
    pose_loop(rig, [1])
    assert rig.node.sim.scene.gravity == (0.0, 0.0, -3.0)


def test_integer_for_a_double_is_taken_as_a_double(rig):
    # `ros2 param set /hair_sim damping 2` sends an integer; the node converts it
    res = set_(rig, damping=2)
    assert res[0].successful, res[0].reason
    value = call(rig, rig.client.get_parameters(['damping']), 'get').values[0]
    assert value.type == ParameterType.PARAMETER_DOUBLE and value.double_value == 2.0
    assert rig.node.parameters.pending.scene.damping == 2.0
    res = set_(rig, gravity=[0, 0, -3])                              # an all-integer list too
    assert res[0].successful, res[0].reason
    assert rig.node.parameters.pending.scene.gravity == (0.0, 0.0, -3.0)


@pytest.mark.parametrize('name, value, reason', [
    ('groom.guides', 0, 'groom.guides: 0 is outside the allowed range [1, 100000]'),
    ('groom.guides', 100001, 'groom.guides: 100001 is outside the allowed range [1, 100000]'),
    ('publish_rate_hz', 0.1, 'publish_rate_hz: 0.1 is outside the allowed range [0.5, 1000.0]'),
    ('publish_rate_hz', float('nan'),
     'publish_rate_hz: nan is outside the allowed range [0.5, 1000.0]'),
    ('solver.stiffness', 0.0, 'solver.stiffness: 0.0 is outside the allowed range (0.0, 1.0]'),
    ('damping', -1, 'damping: -1.0 is outside the allowed range [0.0, 1000.0]'),
])
def test_out_of_range_is_refused_in_the_readme_form(rig, name, value, reason):
    res = call(rig, rig.client.set_parameters([Parameter(name, value=value)]), 'set').results
    assert not res[0].successful and res[0].reason == reason


def test_integer_overrides_of_doubles_at_start_are_taken_as_doubles():
    """`-p damping:=2` at start (rclpy refuses an integer for a double parameter): the node
    declares the double it means, through rclpy's public API; a value that is not a number is
    still refused, naming the parameter."""
    h = Harness(overrides={'damping': 2, 'gravity': [0, 0, -3]}, domain_id=next(_DOMAINS))
    try:
        damping = h.node.get_parameter('damping')
        assert damping.type_ == Parameter.Type.DOUBLE and damping.value == 2.0
        gravity = h.node.get_parameter('gravity')
        assert gravity.type_ == Parameter.Type.DOUBLE_ARRAY
        assert list(gravity.value) == [0.0, 0.0, -3.0]
        assert h.node.settings.scene.damping == 2.0
        assert h.node.settings.scene.gravity == (0.0, 0.0, -3.0)
        assert h.node.describe_parameter('damping').additional_constraints == '[0.0, 1000.0]'
    finally:
        h.close()
    from rclpy.context import Context
    from rclpy.exceptions import InvalidParameterTypeException
    from hair_tracking.ros.node import HairSimNode
    ctx = Context()
    rclpy.init(context=ctx, domain_id=next(_DOMAINS))
    try:
        with pytest.raises(InvalidParameterTypeException, match='damping'):
            HairSimNode(context=ctx, parameter_overrides=[Parameter('damping', value='soft')])
    finally:
        rclpy.try_shutdown(context=ctx)


@pytest.mark.parametrize('name, value, words', [
    ('solver.type', 'rk4', ['solver.type', 'ftl, pbd, xpbd']),
    ('solver.stiffness', 0.0, ['solver.stiffness', '(0.0, 1.0]']),
    ('groom.guides', 0, ['groom.guides', '1', '100000']),
    ('publish_rate_hz', 5000.0, ['publish_rate_hz', '1000']),
    ('marker_color', [1.0, 0.0, 0.0], ['marker_color', '4 numbers']),
    ('groom.scalp.front_max_polar_deg', 150.0, ['groom.scalp.front_max_polar_deg',
                                                'groom.scalp.max_polar_deg']),
    ('warmup', False, ['read-only', 'warmup']),
    ('gravity', '[0.0, 0.0, -3]', ['Wrong parameter type']),
    ('gravity', [0.0, 0.0, 1e4], ['gravity', 'magnitude below 1e4']),
    ('head_track.max_gap', 0.0, ['head_track.max_gap', '(0.0, 3600.0]']),
])
def test_invalid_change_is_rejected_with_its_reason_and_changes_nothing(
        rig, name, value, words):
    before = rig.node.parameters.pending
    before_value = call(rig, rig.client.get_parameters([name]), 'get').values[0]
    res = call(rig, rig.client.set_parameters([Parameter(name, value=value)]), 'set').results
    assert not res[0].successful
    for w in words:
        assert w in res[0].reason, (w, res[0].reason)
    assert rig.node.parameters.pending is before
    after_value = call(rig, rig.client.get_parameters([name]), 'get').values[0]
    assert after_value == before_value


def test_shape_change_rebuilds_the_hair_at_the_current_head(rig):
    rig.listen()
    t = pose_loop(rig, [0, 1], x=0.3)
    assert rig.cloud_at(t).height == 12
    assert all(r.successful for r in set_(rig, groom__guides=2, groom__ghost_nodes=5))
    t2 = pose_loop(rig, [2], x=0.3)
    assert rig.node.rebuilds == 1                        # two changes, one rebuild
    cloud = rig.cloud_at(t2)
    assert (cloud.height, cloud.width) == (6, 5)
    pts, _ = pointcloud2_to_strands(cloud)
    np.testing.assert_allclose(roots_in_head(pts, [0.3, 0.0, 0.0], yaw_quat(0.0)),
                               rig.node.sim.ghosts.rest[:, 0], atol=2e-5)

    def rebuilt():
        return next((a for a in rig.markers
                     if any(len(m.points) == 2 * 6 * 4 for m in a.markers)), None)
    rig.spin_until(lambda: rebuilt() is not None, what='markers of the rebuilt hair')
    arr = rebuilt()
    assert arr.markers[0].action == Marker.DELETEALL                 # strand count changed


def test_load_sets_what_a_params_file_holds(rig, tmp_path):
    path = tmp_path / 'tune.yaml'
    path.write_text(yaml.safe_dump({'hair_sim': {'ros__parameters': {
        'marker_width': 0.004, 'solver': {'type': 'pbd', 'iterations': 8},
        'tracking': {'candidates': 0}}}}))
    res = call(rig, rig.client.load_parameter_file(str(path)), 'load').results
    assert sorted(r.successful for r in res) == [False, True, True, True]
    bad = [r for r in res if not r.successful][0]
    assert 'tracking.candidates' in bad.reason
    s = rig.node.parameters.pending
    assert (s.marker_width, s.scene.solver.type, s.scene.solver.iterations) == (0.004, 'pbd', 8)
    assert s.scene.tracking.candidates == Scene().tracking.candidates
    pose_loop(rig, [0])
    assert rig.node.sim.scene.solver.type == 'pbd'


def test_rates_and_threads_change_live(rig):
    assert set_(rig, publish_rate_hz=10.0)[0].successful
    assert rig.node._publish_timer.timer_period_ns == 100_000_000
    assert set_(rig, publish_rate_hz=25.0)[0].successful       # twice before any step
    assert rig.node._publish_timer.timer_period_ns == 40_000_000
    assert set_(rig, diagnostics_rate_hz=4.0)[0].successful
    assert rig.node._diag_timer.timer_period_ns == 250_000_000
    try:
        assert set_(rig, numba_threads=1)[0].successful
        assert numba.get_num_threads() == 1 == rig.node.numba_threads
        assert set_(rig, numba_threads=0)[0].successful
        assert numba.get_num_threads() == numba.config.NUMBA_NUM_THREADS
    finally:
        numba.set_num_threads(numba.config.NUMBA_NUM_THREADS)


def test_groom_file_is_imported_live_and_a_bad_one_refused_keeping_the_hair(rig, tmp_path):
    import groom_files as gf
    good = tmp_path / 'styled.ply'
    gf.write_ply(good, gf.to_file_frame(gf.synthetic_groom(30, 10, seed=2)))
    rig.listen()
    pose_loop(rig, [0])
    assert set_(rig, groom__file=str(good))[0].successful
    t = pose_loop(rig, [1])
    assert rig.node.rebuilds == 1 and rig.node.sim.ghosts.count == 30
    assert (rig.cloud_at(t).height, rig.cloud_at(t).width) == (30, 6)
    data = good.read_bytes()
    bad = tmp_path / 'cut.ply'
    bad.write_bytes(data[:len(data) // 2])
    res = set_(rig, groom__file=str(bad))[0]
    assert not res.successful
    assert res.reason.startswith('groom.file: ') and 'cut.ply: byte' in res.reason
    assert '\n' not in res.reason
    t = pose_loop(rig, [2])
    assert rig.node.rebuilds == 1 and rig.node.sim.scene.groom.file == str(good)
    assert rig.cloud_at(t).height == 30


def test_a_node_started_with_a_bad_groom_file_names_it(tmp_path):
    from test_node import SMALL
    from hair_tracking.ros.node import HairSimNode
    import rclpy
    from rclpy.context import Context
    bad = tmp_path / 'bad.data'
    bad.write_bytes(np.int32(-1).tobytes())
    ctx = Context()
    rclpy.init(context=ctx, domain_id=next(_DOMAINS))
    try:
        with pytest.raises(ParamError, match=r'groom.file: .*bad.data: byte 0: expected'):
            HairSimNode(context=ctx, parameter_overrides=[
                Parameter(k, value=v) for k, v in dict(SMALL, **{
                    'groom.file': str(bad)}).items()])
    finally:
        rclpy.shutdown(context=ctx)


def test_an_independent_client_finds_sliders_and_the_node_s_refusal():
    """As a new ROS user's tool (rqt's parameter editor) sees the node: a client node of its
    own, in its own context, over DDS through the standard parameter services, finds a
    writable double with a FloatingPointRange and an integer with an IntegerRange, and an
    out-of-range set is refused with the node's one-line message."""
    from rcl_interfaces.msg import ParameterType as T
    from rcl_interfaces.srv import DescribeParameters, ListParameters, SetParameters
    from rclpy.context import Context
    from rclpy.executors import SingleThreadedExecutor
    from rclpy.node import Node

    domain = next(_DOMAINS)
    h = Harness(domain_id=domain)
    ctx = Context()
    rclpy.init(context=ctx, domain_id=domain)
    try:
        client_node = Node('rqt_like', context=ctx)
        executor = SingleThreadedExecutor(context=ctx)
        executor.add_node(client_node)

        def call(srv_type, name, request):
            cli = client_node.create_client(srv_type, f'/hair_sim/{name}')
            future = {}

            def ready():
                executor.spin_once(timeout_sec=0.0)
                if 'f' not in future and cli.service_is_ready():
                    future['f'] = cli.call_async(request)
                return 'f' in future and future['f'].done()
            h.spin_until(ready, what=name)
            return future['f'].result()

        names = call(ListParameters, 'list_parameters', ListParameters.Request()).result.names
        described = call(DescribeParameters, 'describe_parameters',
                         DescribeParameters.Request(names=list(names))).descriptors
        double = next(d for d in described if d.type == T.PARAMETER_DOUBLE and
                      not d.read_only and d.floating_point_range)
        integer = next(d for d in described if d.type == T.PARAMETER_INTEGER and
                       not d.read_only and d.integer_range)
        for d, over in ((double, double.floating_point_range[0].to_value * 2 + 1.0),
                        (integer, integer.integer_range[0].to_value + 1)):
            value = Parameter(d.name, value=over).to_parameter_msg()
            result = call(SetParameters, 'set_parameters',
                          SetParameters.Request(parameters=[value])).results[0]
            assert not result.successful
            assert result.reason == f'{d.name}: {over!r} is outside the allowed range ' \
                f'{d.additional_constraints}', result.reason
            assert '\n' not in result.reason
        executor.shutdown()
        client_node.destroy_node()
    finally:
        rclpy.try_shutdown(context=ctx)
        h.close()
