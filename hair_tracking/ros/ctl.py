"""``hair_sim_ctl``: the ``ros2 param`` and ``ros2 service call ~/reset`` habits without ros2cli.

    hair_sim_ctl param list /hair_sim
    hair_sim_ctl param get /hair_sim solver.type
    hair_sim_ctl param set /hair_sim gravity "[0.0, 0.0, -3.0]"
    hair_sim_ctl param dump /hair_sim > my_hair.yaml
    hair_sim_ctl reset /hair_sim

It talks to a running node through rclpy's own parameter client
(:class:`rclpy.parameter_client.AsyncParameterClient`, what ``ros2 param`` uses) and the node's
``~/reset`` service.  Values are parsed as YAML, as ``ros2 param set`` does: ``-3`` is an
integer, ``-3.0`` a double (hair_sim takes an integer for a double parameter; other nodes may
refuse it, so write the decimal point).
Exit codes: 0 done (or stopped by SIGINT / SIGTERM), 1 the node refused or did not answer,
2 bad command line (a parameter the node does not have is named with the closest one it has).
"""
import argparse
import sys
import time
from typing import List, Optional

import yaml

from hair_tracking import executable, shutdown
from hair_tracking.core.params import did_you_mean

TIMEOUT_S = 10.0


class _Stopped(Exception):
    """A stop was asked for while waiting for the node."""


class _Waits:
    """The waits of one command: for services, for answers; each ends early on a stop."""

    def __init__(self, executor, stop: shutdown.StopRequest, timeout_s: float):
        self.executor, self.stop, self.timeout_s = executor, stop, timeout_s

    def until_ready(self, ready) -> bool:
        """Poll ``ready()`` (graph state, kept by the middleware) until true or the timeout."""
        deadline = time.monotonic() + self.timeout_s
        while not ready():
            left = deadline - time.monotonic()
            if left <= 0:
                return False
            if self.stop.wait(min(left, 0.1)):
                raise _Stopped
        return True

    def answer(self, future):
        """The result of ``future`` (a service call), spinning the executor for it."""
        shutdown.spin_until_stopped(self.executor, self.stop, future, self.timeout_s)
        if self.stop.requested:
            raise _Stopped
        if not future.done():
            raise TimeoutError(f'no answer within {self.timeout_s:g} s')
        return future.result()


def _value(p):
    """The Python value of an rcl_interfaces ParameterValue."""
    from rclpy.parameter import parameter_value_to_python
    return parameter_value_to_python(p)


def _unknown_name(name: str, target: str, names) -> Optional[str]:
    """``None`` when ``target`` has a parameter ``name``, else one line saying so, with the
    closest name it has if one is close (:func:`~hair_tracking.core.params.did_you_mean`)."""
    names = list(names)
    if name in names:
        return None
    hint = did_you_mean(name, names) or f' (hair_sim_ctl param list {target} lists them)'
    return f"unknown parameter '{name}' of {target}{hint}"


def run(args, node, wait: _Waits) -> int:
    from rcl_interfaces.msg import ParameterType
    from rclpy.parameter import Parameter
    from rclpy.parameter_client import AsyncParameterClient
    target = args.node
    if args.cmd == 'reset':
        from std_srvs.srv import Trigger
        cli = node.create_client(Trigger, f'{target.rstrip("/")}/reset')
        if not wait.until_ready(cli.service_is_ready):
            print(f'hair_sim_ctl: {target}/reset is not available', file=sys.stderr)
            return 1
        res = wait.answer(cli.call_async(Trigger.Request()))
        print(res.message or ('reset' if res.success else 'refused'))
        return 0 if res.success else 1
    client = AsyncParameterClient(node, target)
    if not wait.until_ready(client.services_are_ready):
        print(f'hair_sim_ctl: node {target} has no parameter services (is it running?)',
              file=sys.stderr)
        return 1
    if args.action == 'list':
        res = wait.answer(client.list_parameters())
        for name in sorted(res.result.names):
            print(name)
        return 0
    if args.action in ('get', 'set'):
        unknown = _unknown_name(args.name, target,
                                wait.answer(client.list_parameters()).result.names)
        if unknown:
            print(f'hair_sim_ctl: {unknown}', file=sys.stderr)
            return 2
    if args.action in ('get', 'dump'):
        if args.action == 'get':
            names = [args.name]
        else:
            names = sorted(wait.answer(client.list_parameters()).result.names)
        res = wait.answer(client.get_parameters(names))
        got = list(res.values)
        values = {}
        for i, name in enumerate(names):
            if i >= len(got) or got[i].type == ParameterType.PARAMETER_NOT_SET:
                print(f'hair_sim_ctl: parameter {name} is not set', file=sys.stderr)
                return 1
            values[name] = _value(got[i])
        if args.action == 'get':
            print(yaml.safe_dump(values[args.name], default_flow_style=True).strip()
                  .removesuffix('...').strip())
        else:
            key = target if target.startswith('/') else '/' + target
            print(yaml.safe_dump({key: {'ros__parameters': values}}, sort_keys=False), end='')
        return 0
    # set
    try:
        value = yaml.safe_load(args.value)
    except yaml.YAMLError as e:
        print(f'hair_sim_ctl: value {args.value!r} is not YAML: {e}', file=sys.stderr)
        return 2
    if isinstance(value, list) and all(isinstance(v, (int, float)) for v in value) and \
            any(isinstance(v, float) for v in value):
        value = [float(v) for v in value]
    res = wait.answer(client.set_parameters([Parameter(args.name, value=value)]))
    result = res.results[0]
    if not result.successful:
        print(f'hair_sim_ctl: setting {args.name} failed: {result.reason}', file=sys.stderr)
        return 1
    print(f'set {args.name} = {value!r}')
    return 0


def main(argv: Optional[List[str]] = None) -> int:
    ap = argparse.ArgumentParser(prog='hair_sim_ctl', description=__doc__.split('\n')[0])
    ap.add_argument('--timeout', type=float, default=TIMEOUT_S,
                    help=f'seconds to wait for the node (default {TIMEOUT_S:g})')
    sub = ap.add_subparsers(dest='cmd', required=True)
    p = sub.add_parser('param', help='list / get / set / dump parameters of a running node')
    psub = p.add_subparsers(dest='action', required=True)
    for action in ('list', 'dump'):
        a = psub.add_parser(action)
        a.add_argument('node', help='node name, e.g. /hair_sim')
    a = psub.add_parser('get')
    a.add_argument('node')
    a.add_argument('name')
    a = psub.add_parser('set', help='value as YAML: -3 is an integer, -3.0 a double')
    a.add_argument('node')
    a.add_argument('name')
    a.add_argument('value')
    r = sub.add_parser('reset', help="call the node's ~/reset service")
    r.add_argument('node')
    args = ap.parse_args(argv)
    with executable.started() as stop:
        import rclpy
        from rclpy.executors import SingleThreadedExecutor
        from rclpy.signals import SignalHandlerOptions
        rclpy.init(signal_handler_options=SignalHandlerOptions.NO)
        node = rclpy.create_node('hair_sim_ctl')
        executor = SingleThreadedExecutor()
        executor.add_node(node)
        try:
            return run(args, node, _Waits(executor, stop, args.timeout))
        except TimeoutError as e:
            print(f'hair_sim_ctl: {e}', file=sys.stderr)
            return 1
        except _Stopped:
            print(f'hair_sim_ctl: stopped ({stop.signal_name})', file=sys.stderr)
            return 0
        finally:
            executor.shutdown(timeout_sec=1.0)
            node.destroy_node()
            rclpy.try_shutdown()


if __name__ == '__main__':
    sys.exit(main())
