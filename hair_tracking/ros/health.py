"""The ``hair_sim`` node's health on ``/diagnostics``: timings, substeps, stretch, head
penetration, rejected poses, the head pose's and the TF frames' ages, load shedding (one
DiagnosticStatus, sent at ``diagnostics_rate_hz`` whether or not anyone listens: an aggregator
expects a steady rate)."""
from diagnostic_msgs.msg import DiagnosticArray, DiagnosticStatus

from hair_tracking.output.diagnostics import HairHealth, make_status, status_name, WARN
from hair_tracking.ros.topics import diagnostic_status

#: Ghost strands whose stretch and head penetration one diagnostics report checks; a larger hair
#: is checked a part per report, in turn.  A whole-hair check of 100 k ghosts takes about 30 ms
#: of the executor's thread, during which the poses behind it wait.
DIAG_AUDIT_STRANDS = 4096


class NodeHealth:
    """The diagnostics of ``node`` (a :class:`~hair_tracking.ros.node.HairSimNode`)."""

    def __init__(self, node):
        self._node = node
        self.pub = node.create_publisher(DiagnosticArray, '/diagnostics', 10)
        self.sent = 0
        self._health = HairHealth()      # substeps dropped, poses rejected since a report
        self._audit_part = 0             # the part of the ghosts the next report checks

    def status(self) -> DiagnosticStatus:
        """The node's health now (one status)."""
        node = self._node
        sim, s, intake, publishing = node.sim, node.settings, node.intake, node.publishing
        problems = []
        now_ns = node.get_clock().now().nanoseconds
        if intake.last_arrival_ns is None:
            problems = ['waiting for a head pose']
        else:
            age = (now_ns - intake.last_arrival_ns) * 1e-9
            if age > s.stale_timeout:
                problems.append(f'head pose stale for {age:.1f} s (holding the last pose)')
        problems += self._health.problems(sim, intake.rejected)
        if sim.track_once_per_call:
            problems.append('load shedding: ghosts tracked once per pose to keep up')
        frame_problems, body_age = node.scene_frames.problems(now_ns, s.stale_timeout)
        problems += frame_problems
        step = list(intake.step_ms)[-100:]
        pub = list(publishing.publish_ms)[-100:]
        ghosts = sim.ghosts.count if sim.ghosts is not None else 0
        parts = max(1, -(-ghosts // DIAG_AUDIT_STRANDS))
        part = self._audit_part % parts
        self._audit_part = part + 1
        stretch, depth, checked = sim.audit(part, parts)
        values = {
            'step_ms_last': f'{step[-1]:.3f}' if step else 'n/a',
            'step_ms_max_recent': f'{max(step):.3f}' if step else 'n/a',
            'publish_ms_last': f'{pub[-1]:.3f}' if pub else 'n/a',
            'publish_ms_max_recent': f'{max(pub):.3f}' if pub else 'n/a',
        }
        values.update(HairHealth.values(sim, stretch, depth, intake.rejected, node.rebuilds,
                                        checked))
        gravity = node.scene_frames.gravity_used
        values.update({
            'stream_offset_ms': f'{intake.clock.offset_ns * 1e-6:.3f}',
            'numba_threads': str(node.numba_threads),
            'load_shedding': 'active' if sim.track_once_per_call else
                             ('ready' if s.load_shedding else 'off'),
            'load_shedding_switches': str(node.shedder.switches),
            'ghost_kernel': 'none' if sim.ghost_tracker is None else
                            ('parallel' if sim.ghost_tracker.stats['parallel'] else 'serial'),
            'output_frame': publishing.output_frame_id(),
            'tf_sent': str(node.frames.sent),
            'gravity_in_pose_frame': 'n/a' if gravity is None else
                                     ' '.join(f'{v:.4f}' for v in gravity),
            'body_frame_age_s': body_age,
        })
        if publishing.guide_state_pub is not None:
            values['guide_states_sent'] = str(publishing.guide_states_sent)
        if node.faces is not None:                      # people.source hri
            face_problems, face_values = node.faces.diagnostics()
            problems += face_problems
            values.update(face_values)
        return diagnostic_status(status_name(node.get_name()),
                                 make_status(WARN if problems else 0, problems, values))

    def on_timer(self) -> None:
        """One report on ``/diagnostics``."""
        msg = DiagnosticArray(status=[self.status()])
        msg.header.stamp = self._node.get_clock().now().to_msg()
        self.pub.publish(msg)
        self.sent += 1
