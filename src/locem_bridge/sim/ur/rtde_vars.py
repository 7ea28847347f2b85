"""The RTDE variable table of a UR e-Series controller (5.x), as data, plus recipe codecs.

The table follows the "Real-Time Data Exchange (RTDE) guide" of Universal Robots: every variable has a name, an
RTDE type and a direction (``out``: controller → client, ``in``: client → controller; input registers can also be
read back as outputs, as on the real controller). Register families are written as ``name_{a..b}`` and expanded.

A :class:`OutputRecipe` / :class:`InputRecipe` is built once per recipe from its field list; it precomputes one
``struct.Struct`` so that packing a 500 Hz data package is a single ``pack_into`` call.
"""
import re
import struct
from itertools import chain
from typing import Dict, List, Optional, Sequence, Tuple

# RTDE type name -> (struct format, number of elements, python element type)
RTDE_TYPES: Dict[str, Tuple[str, int, type]] = {
    "BOOL": ("?", 1, bool),
    "UINT8": ("B", 1, int),
    "UINT32": ("I", 1, int),
    "UINT64": ("Q", 1, int),
    "INT32": ("i", 1, int),
    "DOUBLE": ("d", 1, float),
    "VECTOR3D": ("3d", 3, float),
    "VECTOR6D": ("6d", 6, float),
    "VECTOR6INT32": ("6i", 6, int),
    "VECTOR6UINT32": ("6I", 6, int),
}

# (name or pattern, type, direction) — direction "out", "in" or "inout" (input variables readable as outputs).
_TABLE_TEXT = """
timestamp                         DOUBLE         out
target_q                          VECTOR6D       out
target_qd                         VECTOR6D       out
target_qdd                        VECTOR6D       out
target_current                    VECTOR6D       out
target_moment                     VECTOR6D       out
actual_q                          VECTOR6D       out
actual_qd                         VECTOR6D       out
actual_current                    VECTOR6D       out
actual_current_window             VECTOR6D       out
joint_control_output              VECTOR6D       out
actual_TCP_pose                   VECTOR6D       out
actual_TCP_speed                  VECTOR6D       out
actual_TCP_force                  VECTOR6D       out
target_TCP_pose                   VECTOR6D       out
target_TCP_speed                  VECTOR6D       out
actual_digital_input_bits         UINT64         out
joint_temperatures                VECTOR6D       out
actual_execution_time             DOUBLE         out
robot_mode                        INT32          out
joint_mode                        VECTOR6INT32   out
safety_mode                       INT32          out
safety_status                     INT32          out
actual_tool_accelerometer         VECTOR3D       out
speed_scaling                     DOUBLE         out
target_speed_fraction             DOUBLE         out
actual_momentum                   DOUBLE         out
actual_main_voltage               DOUBLE         out
actual_robot_voltage              DOUBLE         out
actual_robot_current              DOUBLE         out
actual_joint_voltage              VECTOR6D       out
actual_digital_output_bits        UINT64         out
runtime_state                     UINT32         out
elbow_position                    VECTOR3D       out
elbow_velocity                    VECTOR3D       out
robot_status_bits                 UINT32         out
safety_status_bits                UINT32         out
analog_io_types                   UINT32         out
standard_analog_input0            DOUBLE         out
standard_analog_input1            DOUBLE         out
standard_analog_output0           DOUBLE         out
standard_analog_output1           DOUBLE         out
io_current                        DOUBLE         out
euromap67_input_bits              UINT32         out
euromap67_output_bits             UINT32         out
euromap67_24V_voltage             DOUBLE         out
euromap67_24V_current             DOUBLE         out
tool_mode                         UINT32         out
tool_analog_input_types           UINT32         out
tool_analog_input0                DOUBLE         out
tool_analog_input1                DOUBLE         out
tool_output_voltage               INT32          out
tool_output_current               DOUBLE         out
tool_temperature                  DOUBLE         out
tcp_force_scalar                  DOUBLE         out
output_bit_registers0_to_31       UINT32         out
output_bit_registers32_to_63      UINT32         out
output_bit_register_{64..127}     BOOL           out
output_int_register_{0..47}       INT32          out
output_double_register_{0..47}    DOUBLE         out
tool_output_mode                  UINT8          out
tool_digital_output0_mode         UINT8          out
tool_digital_output1_mode         UINT8          out
payload                           DOUBLE         out
payload_cog                       VECTOR3D       out
payload_inertia                   VECTOR6D       out
script_control_line               UINT32         out
ft_raw_wrench                     VECTOR6D       out
joint_position_deviation_ratio    DOUBLE         out
collision_detection_ratio         DOUBLE         out
speed_slider_mask                 UINT32         in
speed_slider_fraction             DOUBLE         in
standard_digital_output_mask      UINT8          in
standard_digital_output           UINT8          in
configurable_digital_output_mask  UINT8          in
configurable_digital_output       UINT8          in
tool_digital_output_mask          UINT8          in
tool_digital_output               UINT8          in
standard_analog_output_mask       UINT8          in
standard_analog_output_type       UINT8          in
standard_analog_output_0          DOUBLE         in
standard_analog_output_1          DOUBLE         in
external_force_torque             VECTOR6D       in
input_bit_registers0_to_31        UINT32         inout
input_bit_registers32_to_63       UINT32         inout
input_bit_register_{64..127}      BOOL           inout
input_int_register_{0..47}        INT32          inout
input_double_register_{0..47}     DOUBLE         inout
"""

_RANGE = re.compile(r"^(.*)\{(\d+)\.\.(\d+)\}$")


def _expand_table(text: str) -> Tuple[Dict[str, str], Dict[str, str]]:
    outputs: Dict[str, str] = {}
    inputs: Dict[str, str] = {}
    for line in text.strip().splitlines():
        name, typ, direction = line.split()
        if typ not in RTDE_TYPES:
            raise ValueError("RTDE table: unknown type %r for %r" % (typ, name))
        m = _RANGE.match(name)
        names = [m.group(1) + str(i) for i in range(int(m.group(2)), int(m.group(3)) + 1)] if m else [name]
        for n in names:
            if direction in ("out", "inout"):
                outputs[n] = typ
            if direction in ("in", "inout"):
                inputs[n] = typ
    return outputs, inputs


#: name -> RTDE type for every variable a client may request as output.
OUTPUT_VARIABLES, INPUT_VARIABLES = _expand_table(_TABLE_TEXT)


def default_value(typ: str) -> tuple:
    """The zero value of an RTDE type, as the flat tuple that is packed on the wire."""
    _fmt, n, pytype = RTDE_TYPES[typ]
    return (pytype(0),) * n


class OutputRecipe:
    """A validated output recipe: field names, their types, and a precompiled packer for data packages.

    ``types`` holds ``NOT_FOUND`` for unknown names; such a recipe is answered but never streamed (``valid`` False).
    """

    __slots__ = ("recipe_id", "names", "types", "valid", "frequency", "decimation", "_struct", "_buf", "_getter")

    def __init__(self, recipe_id: int, names: Sequence[str], frequency: float, control_rate: float) -> None:
        self.recipe_id = recipe_id
        self.names = list(names)
        self.types = [OUTPUT_VARIABLES.get(n, "NOT_FOUND") for n in self.names]
        self.valid = bool(self.names) and "NOT_FOUND" not in self.types
        self.frequency = frequency
        self.decimation = max(1, int(round(control_rate / frequency))) if frequency > 0 else 1
        self._struct: Optional[struct.Struct] = None
        self._buf = bytearray()
        if self.valid:
            fmt = ">HBB" + "".join(RTDE_TYPES[t][0] for t in self.types)
            self._struct = struct.Struct(fmt)
            self._buf = bytearray(self._struct.size)
            self._getter = None

    @property
    def missing(self) -> List[str]:
        """Names the controller does not know."""
        return [n for n, t in zip(self.names, self.types) if t == "NOT_FOUND"]

    def pack(self, values: Dict[str, tuple]) -> bytearray:
        """Pack one RTDE data package (header included) from ``values`` (name -> flat tuple).

        Returns an internal buffer that is overwritten by the next call: copy or send it at once.
        """
        st = self._struct
        st.pack_into(self._buf, 0, st.size, 85, self.recipe_id,
                     *chain.from_iterable(map(values.__getitem__, self.names)))
        return self._buf


class InputRecipe:
    """A validated input recipe; :meth:`decode` turns a data package payload into ``(name, value)`` pairs."""

    __slots__ = ("recipe_id", "names", "types", "valid", "_struct", "_slices")

    def __init__(self, recipe_id: int, names: Sequence[str], in_use: Sequence[str] = ()) -> None:
        self.recipe_id = recipe_id
        self.names = list(names)
        types = []
        for n in self.names:
            if n not in INPUT_VARIABLES:
                types.append("NOT_FOUND")
            elif n in in_use:
                types.append("IN_USE")
            else:
                types.append(INPUT_VARIABLES[n])
        self.types = types
        self.valid = bool(self.names) and all(t in RTDE_TYPES for t in types)
        self._struct: Optional[struct.Struct] = None
        self._slices: List[Tuple[str, int, int, bool]] = []
        if self.valid:
            self._struct = struct.Struct(">" + "".join(RTDE_TYPES[t][0] for t in types))
            pos = 0
            for n, t in zip(self.names, types):
                k = RTDE_TYPES[t][1]
                self._slices.append((n, pos, pos + k, k == 1))
                pos += k

    @property
    def payload_size(self) -> int:
        return self._struct.size if self._struct is not None else 0

    def decode(self, payload: bytes) -> List[Tuple[str, object]]:
        """Decode the payload after the recipe id byte. Raises ``struct.error`` on a wrong length."""
        flat = self._struct.unpack(payload)
        return [(n, flat[a] if scalar else flat[a:b]) for n, a, b, scalar in self._slices]
