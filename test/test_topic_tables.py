"""The topic tables of README.md and docs/node.md, and ``hair_sim_node --help``, name every topic
the node publishes: a real node (in-process, over DDS, domains 96 and 99) is asked for its
publishers, with every feature on; a node with the defaults advertises only what it feeds.
"""
import os
import re

from rclpy.parameter import Parameter

from hair_tracking.ros.node import make_parser

from test_node import Harness

ROOT = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))
DOMAIN = 96
DOMAIN_DEFAULTS = 99
DOMAIN_LIVE = 101
#: Every feature that has a topic of its own on.
EVERYTHING = {'publish_guides': True, 'publish_guide_state': True, 'body.bust': True}
#: What a node with the default parameters feeds: the hair, the head marker, the head pose on
#: /tf and the diagnostics.
FED_BY_DEFAULT = {'/hair/points', '/hair/markers', '/hair/head', '/tf', '/diagnostics'}
#: What rclpy publishes for every node.
RCLPY_OWN = {'/rosout', '/parameter_events'}


def _table(path, heading):
    """Rows (lists of cells) of the first table after ``heading`` in the Markdown ``path``."""
    with open(os.path.join(ROOT, path), encoding='utf-8') as f:
        text = f.read()
    rows = []
    for line in text[text.index(heading):].splitlines()[1:]:
        if line.startswith('|'):
            rows.append([c.strip() for c in line.strip('|').split('|')])
        elif rows:
            break
    return rows[2:]                                  # past the header and its rule


def _outgoing(rows, direction_column):
    """The absolute names of the topics whose direction cell starts with 'out'."""
    names = set()
    for row in rows:
        if row[direction_column].startswith('out'):
            names |= {n if n.startswith('/') else '/' + n
                      for n in re.findall(r'`([^`]+)`', row[0])}
    return names


def _advertised(h, ready='/hair/points'):
    """The topics ``h``'s node publishes (rclpy's own left out), once ``ready`` is among
    them."""
    node = h.node
    found = set()

    def listed():
        found.clear()
        found.update(name for name, _ in node.get_publisher_names_and_types_by_node(
            node.get_name(), node.get_namespace()))
        return ready in found
    h.spin_until(listed, what=f'{ready} in the node\'s own graph')
    return found - RCLPY_OWN


def _published(overrides=None, domain=DOMAIN):
    h = Harness(overrides, domain_id=domain)
    try:
        return _advertised(h)
    finally:
        h.close()


def test_tables_and_help_name_every_topic_the_node_publishes():
    published = _published(EVERYTHING)
    assert {'/hair/points', '/hair/head', '/tf', '/diagnostics'} <= published
    assert _outgoing(_table('README.md', '## The node'), 2) == published
    assert _outgoing(_table('docs/node.md', '## Topics'), 2) == published
    described = make_parser().description
    for name in published:
        assert (name if name in ('/tf', '/diagnostics') else name.lstrip('/')) in described, name


def test_a_default_node_advertises_only_the_topics_it_feeds():
    """No publisher for a feature that is off (guides, guide state, scene, colliders)."""
    assert _published(domain=DOMAIN_DEFAULTS) == FED_BY_DEFAULT


def test_publishers_follow_their_features_live():
    """Turning a feature on advertises its topic, turning it off withdraws it."""
    h = Harness(domain_id=DOMAIN_LIVE)
    try:
        def set_(**values):
            for name, value in values.items():
                assert h.node.set_parameters([Parameter(name.replace('__', '.'),
                                                        value=value)])[0].successful
        set_(publish_guides=True)
        assert _advertised(h, '/hair/guides/points') == FED_BY_DEFAULT | {
            '/hair/guides/points', '/hair/guides/markers'}
        set_(publish_guides=False, head_marker=False, publish_tf=False)
        assert _advertised(h) == {'/hair/points', '/hair/markers', '/diagnostics'}
        set_(body__bust=True)
        assert _advertised(h) == {'/hair/points', '/hair/markers', '/diagnostics'}
        set_(head_marker=True)
        assert _advertised(h, '/hair/colliders') == {
            '/hair/points', '/hair/markers', '/diagnostics', '/hair/head', '/hair/colliders'}
    finally:
        h.close()
