"""
Declare a node's parameter table and warn about overrides that name no declared parameter.

A misspelled name in a params file (``--params-file``) or on the command line (``-p``) would
otherwise be ignored without a word. The node is created with rclpy's public option
``automatically_declare_parameters_from_overrides=True`` (:data:`NODE_OPTIONS`): rcl has then
matched the params file's node keys (``/**``, the node's fully qualified name, wildcards)
against this node and rclpy has declared every override that applies to it. What that
declared beyond the table and rclpy's own parameters is an unknown name: one warning line
each, and it is undeclared again. The table's parameters are then declared with their
descriptors (undeclared first if an override declared them), so their overrides, types and
ranges apply exactly as without the option.
"""

import difflib

from .messages import parameter_descriptor

# Passed to rclpy's Node (or LifecycleNode) constructor by every node that uses declare_table.
NODE_OPTIONS = {'automatically_declare_parameters_from_overrides': True}
# Parameters rclpy's Node declares itself (time source, type description service).
RCLPY_PARAMETERS = ('use_sim_time', 'start_type_description_service')


def unknown_override_message(name, known):
    """
    Say, in one line, that an override names no parameter (and which one was meant, if clear).

    Parameters
    ----------
    name : str
        The override's parameter name.
    known : iterable of str
        The node's parameter names.

    """
    close = difflib.get_close_matches(name, list(known), n=1)
    hint = f' (did you mean {close[0]!r}?)' if close else ''
    return (f'parameter override {name!r} (--params-file or -p) names no parameter of this '
            f'node: ignored{hint}')


def declare_table(node, specs):
    """
    Declare every parameter of a table on ``node``; warn about and drop unknown overrides.

    Parameters
    ----------
    node : rclpy.node.Node
        Created with :data:`NODE_OPTIONS`.
    specs : sequence of parameters.ParameterSpec
        The node's parameter table.

    Returns
    -------
    list of str
        The unknown override names, sorted (each warned about once on the node's logger).

    """
    known = {spec.name for spec in specs}
    declared = node.list_parameters([], 0).names   # depth 0: every name, recursively
    unknown = sorted(name for name in declared
                     if name not in known and name not in RCLPY_PARAMETERS)
    for name in unknown:
        node.get_logger().warning(unknown_override_message(name, known))
        node.undeclare_parameter(name)
    for spec in specs:
        if node.has_parameter(spec.name):    # declared from its override, without descriptor
            node.undeclare_parameter(spec.name)
        node.declare_parameter(spec.name, spec.default, parameter_descriptor(spec))
    return unknown
