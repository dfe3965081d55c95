"""The topic tables of README.md and docs/node.md, and ``hair_sim_node --help``, name every topic
the node publishes: a real node (in-process, over DDS, domain 96) is asked for its publishers.
"""
import os
import re

from hair_tracking.ros.node import make_parser

from test_node import Harness

ROOT = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))
DOMAIN = 96
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


def _published():
    h = Harness(domain_id=DOMAIN)
    try:
        node = h.node
        found = set()

        def listed():
            found.clear()
            found.update(name for name, _ in node.get_publisher_names_and_types_by_node(
                node.get_name(), node.get_namespace()))
            return '/hair/points' in found
        h.spin_until(listed, what='the node in its own graph')
        return found - RCLPY_OWN
    finally:
        h.close()


def test_tables_and_help_name_every_topic_the_node_publishes():
    published = _published()
    assert {'/hair/points', '/hair/head', '/tf', '/diagnostics'} <= published
    assert _outgoing(_table('README.md', '## The node'), 2) == published
    assert _outgoing(_table('docs/node.md', '## Topics'), 2) == published
    described = make_parser().description
    for name in published:
        assert (name if name in ('/tf', '/diagnostics') else name.lstrip('/')) in described, name
