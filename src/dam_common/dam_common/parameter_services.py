"""Parameter services that answer every request, however malformed, and never take a node down.

rclpy's own ``~/set_parameters`` and ``~/set_parameters_atomically`` turn each
``rcl_interfaces/Parameter`` into a Python value first; an unknown type code (``{type: 255}``)
raises inside the service callback, the request gets no answer and the exception ends the
node's spin. :func:`harden_parameter_services` replaces the callbacks of those two services on a
node with ones that check each parameter message first and answer ``successful: false`` with
the parameter's name, the field and the value; the read-only services (get, describe, list,
get types) keep rclpy's callbacks behind the catch-all guard of
:func:`dam_common.node.guard_service_callbacks`.
"""

from __future__ import annotations

from rcl_interfaces.msg import Parameter as ParameterMsg
from rcl_interfaces.msg import ParameterType, SetParametersResult
from rcl_interfaces.srv import SetParameters, SetParametersAtomically
from rclpy.exceptions import ParameterException
from rclpy.node import Node
from rclpy.parameter import Parameter

from dam_common.echo import brief_repr, brief_text

#: Type code -> the ParameterValue field that carries the value.
_VALUE_FIELD = {
    ParameterType.PARAMETER_BOOL: 'bool_value',
    ParameterType.PARAMETER_INTEGER: 'integer_value',
    ParameterType.PARAMETER_DOUBLE: 'double_value',
    ParameterType.PARAMETER_STRING: 'string_value',
    ParameterType.PARAMETER_BYTE_ARRAY: 'byte_array_value',
    ParameterType.PARAMETER_BOOL_ARRAY: 'bool_array_value',
    ParameterType.PARAMETER_INTEGER_ARRAY: 'integer_array_value',
    ParameterType.PARAMETER_DOUBLE_ARRAY: 'double_array_value',
    ParameterType.PARAMETER_STRING_ARRAY: 'string_array_value',
}
_TYPE_NAMES = ', '.join(f'{code} ({field.removesuffix("_value")})'
                        for code, field in sorted(_VALUE_FIELD.items()))


def parameter_from_msg(msg: ParameterMsg) -> Parameter:
    """The rclpy Parameter a message describes.

    Raises
    ------
    ValueError
        Empty name, type code ``0`` ("not set": ``ros2 param delete``; our nodes declare every
        parameter they have and none can be deleted), or a code that is not one of
        ``rcl_interfaces/ParameterType``'s. The message names the parameter and the value.
    """
    name = str(msg.name)
    if not name:
        raise ValueError('parameter name is empty')
    quoted = brief_repr(name)
    code = int(msg.value.type)
    if code == ParameterType.PARAMETER_NOT_SET:
        raise ValueError(f'parameter {quoted}: value.type 0 (not set) would delete it; the '
                         f'parameters of this node cannot be deleted')
    if code not in _VALUE_FIELD:
        raise ValueError(f'parameter {quoted}: value.type {code} is not a parameter type '
                         f'(expected one of {_TYPE_NAMES})')
    try:
        return Parameter.from_parameter_msg(msg)
    except (ValueError, TypeError) as exc:
        raise ValueError(f'parameter {quoted}: {brief_text(str(exc))}') from exc


def _refused(reason: str) -> SetParametersResult:
    return SetParametersResult(successful=False, reason=brief_text(reason))


def list_parameters_hint(node: Node) -> str:
    """How a user lists the node's parameters: ``ros2 param list`` where ros2cli is installed
    (a system Jazzy), and the service it calls, which any ROS 2 client has (the PyPI wheels
    ship no ros2cli)."""
    name = node.get_fully_qualified_name()
    return (f'`ros2 param list {name}`, or without ros2cli a call of the service '
            f'{name}/list_parameters (rcl_interfaces/srv/ListParameters)')


def _set(node: Node, parameters: list[Parameter]) -> SetParametersResult:
    """``node.set_parameters_atomically`` that answers any failure with a reason."""
    undeclared = [p.name for p in parameters if not node.has_parameter(p.name)]
    if undeclared:
        return _refused(f'no parameter {", ".join(map(brief_repr, undeclared))} on '
                        f'{node.get_fully_qualified_name()} ({list_parameters_hint(node)} '
                        f'lists them)')
    try:
        return node.set_parameters_atomically(parameters)
    except ParameterException as exc:  # read-only, wrong type, out of range
        return _refused(str(exc))
    except Exception as exc:  # noqa: BLE001 - e.g. an on-set callback that raised
        names = brief_repr([p.name for p in parameters])
        node.get_logger().error(f'setting {names} raised {brief_repr(exc)}')
        return _refused(f'internal error while setting the parameters: {brief_repr(exc)}')


def harden_parameter_services(node: Node) -> None:
    """Replace the set-parameter callbacks of ``node``'s parameter services (no-op without).

    ``~/set_parameters`` answers each parameter on its own; ``~/set_parameters_atomically``
    refuses the whole request when any parameter is malformed.
    """
    fqn = node.get_fully_qualified_name().lstrip('/')

    def set_each(request: SetParameters.Request, response: SetParameters.Response
                 ) -> SetParameters.Response:
        results = []
        for msg in request.parameters:
            try:
                param = parameter_from_msg(msg)
            except ValueError as exc:
                results.append(_refused(str(exc)))
                continue
            results.append(_set(node, [param]))
        response.results = results
        return response

    def set_atomically(request: SetParametersAtomically.Request,
                       response: SetParametersAtomically.Response
                       ) -> SetParametersAtomically.Response:
        try:
            params = [parameter_from_msg(msg) for msg in request.parameters]
        except ValueError as exc:
            response.result = _refused(f'{exc}; no parameter was set')
            return response
        response.result = _set(node, params)
        return response

    replacements = {f'{fqn}/set_parameters': (SetParameters, set_each),
                    f'{fqn}/set_parameters_atomically': (SetParametersAtomically,
                                                         set_atomically)}
    for service in node.services:
        entry = replacements.get(service.srv_name.lstrip('/'))
        if entry is not None and service.srv_type is entry[0]:
            service.callback = entry[1]
