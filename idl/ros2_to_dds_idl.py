#!/usr/bin/python3
"""Writes the DDS IDL of a ROS 2 interface package's .msg/.srv files as ROS 2
middlewares put them on the wire, for idlc.

Each file goes the way rosidl takes it: rosidl_adapter turns the .msg/.srv into
ROS 2 .idl, rosidl_parser reads that; this script then writes the structures
under the names rmw gives their DDS types: module `dds_` inside the package's
`msg` / `srv` module and a trailing underscore on each struct
(`sl_msgs::msg::dds_::Status_`, `sl_msgs::srv::dds_::Start_Request_`,
`sl_msgs::srv::dds_::Start_Response_`). Constants (which never reach the
wire) become `const` declarations in a module `<Type>_Constants` beside the
struct. A type of another package is referred to by its DDS name and
included as `<package>/msg/<Type>.idl`, the layout of idl/.

Services: with --cyclonedds-request-header, each request and response
struct starts with the request header rmw_cyclonedds puts in front of every
service sample (rmw_cyclonedds_cpp/src/serdata.hpp, cdds_request_header_t:
uint64 guid, int64 seq): the client's id and the request's sequence number,
copied from request to response. Without it the structs are the plain ROS 2
message (rmw_fastrtps puts the ids in the RTPS sample identity instead).

usage: ros2_to_dds_idl.py [--cyclonedds-request-header] PACKAGE_DIR OUTPUT_DIR FILE...
(FILE relative to
PACKAGE_DIR, e.g. msg/Status.msg); writes OUTPUT_DIR/<package>/<msg|srv>/<Type>.idl,
and (if there are messages) OUTPUT_DIR/<package>/ros2_definitions.h: each message's .msg text without
comments, as C++ string literals (the `ros2msg` schemas of MCAP and Foxglove).
Must run with the Python that has python3-rosidl (Debian: /usr/bin/python3).
"""

import os
import pathlib
import sys
import tempfile

from rosidl_adapter.msg import convert_msg_to_idl
from rosidl_adapter.srv import convert_srv_to_idl
from rosidl_parser import definition
from rosidl_parser.parser import parse_idl_file


def dds_name(namespaced):
    """The DDS type name rmw uses for a ROS 2 type: pkg::msg::dds_::Type_."""
    return '::'.join(list(namespaced.namespaces) + ['dds_', namespaced.name + '_'])


def element_type(type_, includes):
    if isinstance(type_, definition.BasicType):
        return type_.typename
    if isinstance(type_, definition.NamespacedType):
        # A nested service message (never in .msg/.srv input) would need its
        # own include rule; messages live in <pkg>/msg/<Type>.idl.
        if list(type_.namespaces)[-1] != 'msg':
            raise ValueError(f'field type {"::".join(type_.namespaced_name())} is not a message')
        includes.add('/'.join(list(type_.namespaces) + [type_.name + '.idl']))
        return dds_name(type_)
    if isinstance(type_, definition.BoundedString):
        return f'string<{type_.maximum_size}>'
    if isinstance(type_, definition.UnboundedString):
        return 'string'
    if isinstance(type_, definition.BoundedWString):
        return f'wstring<{type_.maximum_size}>'
    if isinstance(type_, definition.UnboundedWString):
        return 'wstring'
    raise ValueError(f'unsupported type {type_!r}')


def member_declaration(member, includes):
    type_ = member.type
    if isinstance(type_, definition.Array):
        return f'{element_type(type_.value_type, includes)} {member.name}[{type_.size}];'
    if isinstance(type_, definition.BoundedSequence):
        element = element_type(type_.value_type, includes)
        return f'sequence<{element}, {type_.maximum_size}> {member.name};'
    if isinstance(type_, definition.UnboundedSequence):
        return f'sequence<{element_type(type_.value_type, includes)}> {member.name};'
    return f'{element_type(type_, includes)} {member.name};'


def constant_value(constant):
    value = constant.value
    if isinstance(value, bool):
        return 'TRUE' if value else 'FALSE'
    if isinstance(value, str):
        return '"' + value.replace('\\', '\\\\').replace('"', '\\"') + '"'
    return repr(value)


# rmw_cyclonedds's cdds_request_header_t, as members.
REQUEST_HEADER = ['uint64 request_header_guid;', 'int64 request_header_seq;']


def message_lines(message, includes, indent, header=()):
    name = message.structure.namespaced_type.name
    lines = []
    if message.constants:
        lines.append(f'{indent}module {name}_Constants {{')
        for c in message.constants:
            lines.append(f'{indent}  const {element_type(c.type, includes)} {c.name} = '
                         f'{constant_value(c)};')
        lines.append(f'{indent}}};')
    lines.append(f'{indent}struct {name}_ {{')
    lines += [f'{indent}  {m}' for m in header]
    for member in message.structure.members:
        lines.append(f'{indent}  {member_declaration(member, includes)}')
    lines.append(f'{indent}}};')
    return lines


def quiet(function, *args):
    """Calls function with stdout closed: rosidl_adapter prints each file it reads and writes."""
    sys.stdout.flush()
    saved = os.dup(1)
    with open(os.devnull, 'w') as devnull:
        os.dup2(devnull.fileno(), 1)
    try:
        return function(*args)
    finally:
        sys.stdout.flush()
        os.dup2(saved, 1)
        os.close(saved)


def convert(package_dir, package, relative, output_dir, request_header):
    kind = relative.parent.name  # msg or srv
    with tempfile.TemporaryDirectory() as tmp:
        ros_idl_dir = pathlib.Path(tmp) / kind
        ros_idl_dir.mkdir()
        converter = convert_msg_to_idl if relative.suffix == '.msg' else convert_srv_to_idl
        quiet(converter, package_dir, package, relative, ros_idl_dir)
        parsed = parse_idl_file(definition.IdlLocator(tmp, f'{kind}/{relative.stem}.idl'))
    messages = []  # (message, header members)
    for element in parsed.content.elements:
        if isinstance(element, definition.Message):
            messages.append((element, ()))
        elif isinstance(element, definition.Service):
            header = REQUEST_HEADER if request_header else ()
            messages += [(element.request_message, header), (element.response_message, header)]
    if not messages:
        raise ValueError(f'{relative}: no message or service in it')

    includes = set()
    body = []
    for message, header in messages:
        body += message_lines(message, includes, '      ', header)
    guard = f'SL_IDL_{package}_{kind}_{relative.stem}_IDL'.upper()
    lines = [f'// Generated from {package}/{relative} by idl/ros2_to_dds_idl.py: do not edit.',
             f'#ifndef {guard}', f'#define {guard}', '']
    lines += [f'#include "{inc}"' for inc in sorted(includes)]
    lines += ['', f'module {package} {{', f'  module {kind} {{', '    module dds_ {']
    lines += body
    lines += ['    };', '  };', '};', '', '#endif', '']
    write_if_changed(output_dir / package / kind / (relative.stem + '.idl'), '\n'.join(lines))


def write_if_changed(path, text):
    """Rewritten only when it changes, so idlc and its dependants do not rerun."""
    path.parent.mkdir(parents=True, exist_ok=True)
    if not path.exists() or path.read_text() != text:
        path.write_text(text)


def msg_fields(text):
    """A .msg's lines without comments and blank lines ('#' in a string constant kept)."""
    lines = []
    for line in text.splitlines():
        words = line.split()
        if len(words) >= 2 and words[0].startswith('string') and '=' in words[1]:
            lines.append(line.strip())  # a string constant's value runs to the end of the line
            continue
        line = line.split('#', 1)[0].strip()
        if line:
            lines.append(' '.join(line.split()))
    return ''.join(line + '\n' for line in lines)


def definitions_header(package_dir, package, relatives):
    entries = []
    for relative in relatives:
        if relative.suffix != '.msg':
            continue
        fields = msg_fields((package_dir / relative).read_text(encoding='utf-8'))
        literal = fields.replace('\\', '\\\\').replace('"', '\\"').replace('\n', '\\n')
        entries.append(f'    {{"{package}/{relative.stem}", "{literal}"}},')
    return '\n'.join([
        f'// Generated from {package}/msg by idl/ros2_to_dds_idl.py: do not edit.',
        f'// Each message of {package}: its .msg text without comments or blank lines.',
        '#pragma once', '',
        f'namespace {package}_definitions {{', '',
        'struct Definition {',
        '  const char* type;    // "package/Type"',
        '  const char* fields;  // one field or constant per line, each ending in a newline',
        '};', '',
        'inline constexpr Definition kMessages[] = {'] + entries + ['};', '',
        f'}}  // namespace {package}_definitions', ''])


def main(argv):
    request_header = '--cyclonedds-request-header' in argv
    argv = [a for a in argv if a != '--cyclonedds-request-header']
    if len(argv) < 4:
        sys.exit(__doc__)
    package_dir = pathlib.Path(argv[1]).resolve()
    output_dir = pathlib.Path(argv[2])
    package = package_dir.name
    relatives = [pathlib.Path(name) for name in argv[3:]]
    for relative in relatives:
        try:
            convert(package_dir, package, relative, output_dir, request_header)
        except Exception as e:  # rosidl's parsers raise assorted types
            sys.exit(f'ros2_to_dds_idl: {package_dir / relative}: {e}')
    if any(r.suffix == '.msg' for r in relatives):
        write_if_changed(output_dir / package / 'ros2_definitions.h',
                         definitions_header(package_dir, package, relatives))


if __name__ == '__main__':
    main(sys.argv)
