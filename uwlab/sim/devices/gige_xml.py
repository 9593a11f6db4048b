"""GenICam XML (GenApi schema 1.1) and register layout of the GigE Vision simulated camera.

Every feature of `SimNodeMap` gets a big-endian register: integers, enumerations, booleans
and commands a 32-bit `IntReg` at ``INT_BASE + 4·i``; floats a 64-bit IEEE 754 `FloatReg` at
``FLOAT_BASE + 8·i``; strings are the GigE Vision bootstrap strings (GigE Vision 2.0,
table 28). Integer bounds that depend on other features (ROI) are read-only registers the
server computes live (``<pMin>``/``<pMax>``). The XML is served from ``XML_ADDRESS`` and
announced by the bootstrap "first URL" register as ``Local:<file>;<address>;<length>``.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import TYPE_CHECKING
from xml.sax.saxutils import escape

from uwlab.drivers.camera.pixels import PIXEL_FORMATS

if TYPE_CHECKING:
    from uwlab.sim.devices.camera import SimNodeMap

INT_BASE = 0x0002_0000
FLOAT_BASE = 0x0003_0000
XML_ADDRESS = 0x0010_0000
XML_FILE = "uwlab-sim-camera.xml"

STRING_REGISTERS = {  # GigE Vision bootstrap: name -> (address, length)
    "DeviceVendorName": (0x0048, 32),
    "DeviceModelName": (0x0068, 32),
    "DeviceVersion": (0x0088, 32),
    "DeviceFirmwareVersion": (0x0088, 32),
    "DeviceSerialNumber": (0x00D8, 16),
}
ENUM_VALUES = {
    "PixelFormat": {name: pf.code for name, pf in PIXEL_FORMATS.items()},
    "ExposureAuto": {"Off": 0, "Continuous": 2},
    "GainAuto": {"Off": 0, "Continuous": 2},
    "AcquisitionMode": {"Continuous": 2},
    "TriggerSelector": {"FrameStart": 6},
    "TriggerMode": {"Off": 0, "On": 1},
    "TriggerSource": {"Software": 0},
}
INT_FEATURES = (
    "SensorWidth",
    "SensorHeight",
    "Width",
    "Height",
    "OffsetX",
    "OffsetY",
    "BinningHorizontal",
    "BinningVertical",
    "PayloadSize",
    "AcquisitionFrameRateEnable",
    "AcquisitionStart",
    "AcquisitionStop",
    "TriggerSoftware",
    *ENUM_VALUES,
)
DYNAMIC_BOUNDS = ("Width", "Height", "OffsetX", "OffsetY", "BinningHorizontal", "BinningVertical")
FLOAT_FEATURES = ("ExposureTime", "Gain", "BlackLevel", "AcquisitionFrameRate", "DeviceTemperature")
SCPS_ADDRESS = 0x0D04


@dataclass(frozen=True)
class Register:
    """Where a feature (or one of its live bounds, ``part`` = "min"/"max") lives."""

    feature: str
    kind: str
    part: str = "value"


def register_map() -> dict[int, Register]:
    regs: dict[int, Register] = {}
    names = list(INT_FEATURES) + [f"{n}{p}" for n in DYNAMIC_BOUNDS for p in ("Min", "Max")]
    for i, name in enumerate(names):
        base, part = (
            (name[:-3], name[-3:].lower())
            if name.endswith(("Min", "Max")) and name[:-3] in DYNAMIC_BOUNDS
            else (name, "value")
        )
        regs[INT_BASE + 4 * i] = Register(base, "int", part)
    for i, name in enumerate(FLOAT_FEATURES):
        regs[FLOAT_BASE + 8 * i] = Register(name, "float")
    return regs


def _addresses() -> dict[tuple[str, str], int]:
    return {(r.feature, r.part): a for a, r in register_map().items()}


def _int_reg(name: str, address: int, access: str) -> str:
    return (
        f'<IntReg Name="{name}Reg"><Address>0x{address:X}</Address><Length>4</Length>'
        f"<AccessMode>{access}</AccessMode><pPort>Device</pPort><Sign>Unsigned</Sign>"
        "<Endianess>BigEndian</Endianess></IntReg>"
    )


def _feature_xml(name: str, nodes: SimNodeMap, addr: dict[tuple[str, str], int]) -> list[str]:
    node = nodes.nodes[name]
    access = "RW" if node.writable else "RO"
    if name in ENUM_VALUES:
        entries = "".join(
            f'<EnumEntry Name="{e}"><Value>{v}</Value></EnumEntry>'
            for e, v in ENUM_VALUES[name].items()
            if e in node.entries
        )
        return [
            f'<Enumeration Name="{name}" NameSpace="Standard">{entries}<pValue>{name}Reg</pValue></Enumeration>',
            _int_reg(name, addr[(name, "value")], "RW"),
        ]
    if node.kind == "cmd":
        return [
            f'<Command Name="{name}" NameSpace="Standard"><pValue>{name}Reg</pValue>'
            "<CommandValue>1</CommandValue></Command>",
            _int_reg(name, addr[(name, "value")], "WO"),
        ]
    if node.kind == "bool":
        return [
            f'<Boolean Name="{name}" NameSpace="Standard"><pValue>{name}Reg</pValue><OnValue>1</OnValue>'
            f"<OffValue>0</OffValue></Boolean>",
            _int_reg(name, addr[(name, "value")], "RW"),
        ]
    if node.kind == "int":
        if name in DYNAMIC_BOUNDS:
            limits = f"<pMin>{name}MinReg</pMin><pMax>{name}MaxReg</pMax>"
            extra = [
                _int_reg(f"{name}Min", addr[(name, "min")], "RO"),
                _int_reg(f"{name}Max", addr[(name, "max")], "RO"),
            ]
        else:
            limits, extra = "", []
        return [
            f'<Integer Name="{name}" NameSpace="Standard"><pValue>{name}Reg</pValue>{limits}'
            f"<Inc>{node.increment}</Inc></Integer>",
            _int_reg(name, addr[(name, "value")], access),
            *extra,
        ]
    if node.kind == "float":
        lo, hi = node.bounds() if node.bounds else (-1e300, 1e300)
        return [
            f'<Float Name="{name}" NameSpace="Standard"><pValue>{name}Reg</pValue>'
            f"<Min>{lo!r}</Min><Max>{hi!r}</Max></Float>",
            f'<FloatReg Name="{name}Reg"><Address>0x{addr[(name, "value")]:X}</Address><Length>8</Length>'
            f"<AccessMode>{access}</AccessMode><pPort>Device</pPort><Endianess>BigEndian</Endianess></FloatReg>",
        ]
    address, length = STRING_REGISTERS[name]
    return [
        f'<StringReg Name="{name}" NameSpace="Standard"><Address>0x{address:X}</Address><Length>{length}</Length>'
        f"<AccessMode>RO</AccessMode><pPort>Device</pPort></StringReg>"
    ]


def genicam_xml(nodes: SimNodeMap) -> bytes:
    """The device description for a `SimNodeMap` (vendor/model from its string features)."""
    addr = _addresses()
    names = [n for n in nodes.nodes if n in STRING_REGISTERS or n in INT_FEATURES or n in FLOAT_FEATURES]
    body = [part for n in names for part in _feature_xml(n, nodes, addr)]
    body.append(
        f'<Integer Name="GevSCPSPacketSize" NameSpace="Standard"><pValue>GevSCPSPacketSizeReg</pValue>'
        f"<Min>576</Min><Max>65500</Max><Inc>4</Inc></Integer>{_int_reg('GevSCPSPacketSize', SCPS_ADDRESS, 'RW')}"
    )
    features = "".join(f"<pFeature>{n}</pFeature>" for n in [*names, "GevSCPSPacketSize"])
    vendor = escape(str(nodes.value("DeviceVendorName")))
    model = escape(str(nodes.value("DeviceModelName")))
    return (
        '<?xml version="1.0" encoding="utf-8"?>\n'
        f'<RegisterDescription ModelName="{model}" VendorName="{vendor}" StandardNameSpace="GEV" '
        'SchemaMajorVersion="1" SchemaMinorVersion="1" SchemaSubMinorVersion="0" MajorVersion="1" MinorVersion="0" '
        'SubMinorVersion="0" ToolTip="uwlab simulated camera" ProductGuid="7A1E5C3B-0000-4000-8000-000000000001" '
        'VersionGuid="7A1E5C3B-0000-4000-8000-000000000002" xmlns="http://www.genicam.org/GenApi/Version_1_1" '
        'xmlns:xsi="http://www.w3.org/2001/XMLSchema-instance" '
        'xsi:schemaLocation="http://www.genicam.org/GenApi/Version_1_1 http://www.genicam.org/GenApi/GenApiSchema_Version_1_1.xsd">\n'
        f'<Category Name="Root" NameSpace="Standard">{features}</Category>\n'
        + "\n".join(body)
        + '\n<Port Name="Device" NameSpace="Standard"/>\n</RegisterDescription>\n'
    ).encode()
