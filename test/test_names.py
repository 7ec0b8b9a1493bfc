"""names: the output topics of a node and the names every layer shares."""

from flexlink_ros import names
import pytest


@pytest.mark.parametrize('node', ['/ns/node', 'ns/node', '/ns/node/'])
def test_output_topics_are_the_five_topics_under_the_node(node):
    assert names.output_topics(node) == {
        'lever_tip': '/ns/node/lever_tip/deflection',
        'coupler_mid': '/ns/node/coupler_mid/deflection',
        'criteria': '/ns/node/joint_criteria',
        'quality': '/ns/node/quality',
        'markers': '/ns/node/markers'}


def test_the_default_node_publishes_private_topics_and_global_diagnostics():
    topics = names.output_topics(names.NODE_NAME)
    assert all(topic.startswith('/flexlink_node/') for topic in topics.values())
    assert len(set(topics.values())) == 5
    assert names.TOPICS['diagnostics'] == '/diagnostics'   # not under the node


def test_output_names_are_the_x_and_y_of_each_output_point():
    assert names.OUTPUT_NAMES == tuple(f'{point}_{axis}' for point in names.OUTPUT_POINTS
                                       for axis in ('dx', 'dy'))
    assert len(names.JOINT_NAMES) == len(names.LINK_NAMES) + 1   # ground closes the loop
