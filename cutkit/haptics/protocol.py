"""The haptics wire protocol, version 1 (docs/haptics-protocol.md).

Every frame is a 24-byte little-endian header followed by ``length`` payload
bytes.  Each frame type has one fixed payload size, so a receiver can reject
a malformed frame from its header alone.

Pose forwarding is an extension within version 1: a simulation sets
``HELLO_FORWARD_POSES`` in the HELLO flags byte (a pad byte for servers
without it), a server that forwards echoes the bit in WELCOME and sends that
simulation a DEVICE_POSE frame every tick in which a device pose arrived.
"""

from __future__ import annotations

import struct

from cutkit.errors import ProtocolError

MAGIC = b"CKHP"
VERSION = 1

#: magic, version, type, length, sequence, timestamp_ns
HEADER = struct.Struct("<4sHHIIQ")
HEADER_SIZE = HEADER.size  # 24
#: No payload of version 1 is larger; a bigger length field is rejected at once.
MAX_PAYLOAD = 256

# frame types
HELLO = 1  # client -> server, first frame: role
WELCOME = 2  # server -> client: role accepted, client id, tick rate
POSE = 3  # device -> server
FORCE = 4  # server -> device, every tick
SIM_UPDATE = 5  # simulation -> server
STATE = 6  # server -> simulation, in reply to each SIM_UPDATE
BYE = 7  # either way: closing
ERROR = 8  # server -> client before it closes a connection
DEVICE_POSE = 9  # server -> simulation that asked for it: the newest device pose

TYPE_NAMES = {HELLO: "HELLO", WELCOME: "WELCOME", POSE: "POSE", FORCE: "FORCE", SIM_UPDATE: "SIM_UPDATE",
              STATE: "STATE", BYE: "BYE", ERROR: "ERROR", DEVICE_POSE: "DEVICE_POSE"}

# roles
ROLE_DEVICE = 1
ROLE_SIMULATION = 2
ROLE_NAMES = {ROLE_DEVICE: "device", ROLE_SIMULATION: "simulation"}

# payloads
HELLO_PAYLOAD = struct.Struct("<B3x")  # role (a plain HELLO: flags byte zero)
WELCOME_PAYLOAD = struct.Struct("<B3xII")  # role, client id, tick rate Hz (flags byte skipped)
#: The same payloads with the flags byte (offset 1) that pose forwarding uses.
HELLO_FLAGS_PAYLOAD = struct.Struct("<BB2x")  # role, flags (HELLO_* bits)
WELCOME_FLAGS_PAYLOAD = struct.Struct("<BB2xII")  # role, flags granted, client id, tick rate Hz
#: HELLO flag: a simulation asks for DEVICE_POSE frames (the server echoes it in WELCOME if it forwards).
HELLO_FORWARD_POSES = 0x01
#: tip (3), a (3), n (3) as float64; buttons uint32; 4 pad bytes
POSE_PAYLOAD = struct.Struct("<9dI4x")
#: force (3), proxy (3), a (3), n (3), force gain as float64; echo timestamp,
#: tick as uint64; echo sequence uint32; state code uint8; 3 pad bytes
FORCE_PAYLOAD = struct.Struct("<13dQQIB3x")
#: entry (3), plane normal (3), external force (3), material (9) as float64;
#: contact uint8; 7 pad bytes
SIM_PAYLOAD = struct.Struct("<18dB7x")
#: tip (3), a (3), n (3) as float64 exactly as the device sent them; buttons
#: uint32; device client id uint32; header timestamp of that POSE uint64;
#: its header sequence uint32; 4 pad bytes; server tick uint64
DEVICE_POSE_PAYLOAD = struct.Struct("<9dIIQI4xQ")
ERROR_HEAD = struct.Struct("<I")  # error code, then a UTF-8 message to the end of the payload

#: Payload size of each type; None = variable up to MAX_PAYLOAD.
PAYLOAD_SIZE = {HELLO: HELLO_PAYLOAD.size, WELCOME: WELCOME_PAYLOAD.size, POSE: POSE_PAYLOAD.size,
                FORCE: FORCE_PAYLOAD.size, SIM_UPDATE: SIM_PAYLOAD.size, STATE: FORCE_PAYLOAD.size,
                BYE: 0, ERROR: None, DEVICE_POSE: DEVICE_POSE_PAYLOAD.size}

# error codes
E_BAD_MAGIC = 1
E_BAD_VERSION = 2
E_BAD_TYPE = 3
E_BAD_LENGTH = 4
E_OVERSIZED = 5
E_TRUNCATED = 6
E_UNEXPECTED = 7  # a valid frame the connection may not send (no HELLO yet, wrong role)
E_BAD_VALUE = 8  # non-finite numbers, unknown role
E_TIMEOUT = 9  # a frame left incomplete for too long


class FrameError(ProtocolError):
    """A malformed frame; ``code`` is the ERROR code sent back (``E_*``)."""

    def __init__(self, message: str, code: int):
        super().__init__(message)
        self.code = code


def check_header(buf, offset: int = 0):
    """Decode and validate a header; raise FrameError on anything wrong.

    Returns
    -------
    (type, length, sequence, timestamp_ns)
    """
    magic, version, ftype, length, seq, ts = HEADER.unpack_from(buf, offset)
    if magic != MAGIC:
        raise FrameError(f"bad magic {bytes(magic)!r} (expected {MAGIC!r})", E_BAD_MAGIC)
    if version != VERSION:
        raise FrameError(f"bad protocol version {version} (this server speaks {VERSION})", E_BAD_VERSION)
    if length > MAX_PAYLOAD:
        raise FrameError(f"oversized frame: length {length} > {MAX_PAYLOAD}", E_OVERSIZED)
    if ftype not in PAYLOAD_SIZE:
        raise FrameError(f"unknown frame type {ftype}", E_BAD_TYPE)
    want = PAYLOAD_SIZE[ftype]
    if want is not None and length != want:
        raise FrameError(f"bad length {length} for {TYPE_NAMES[ftype]} (expected {want})", E_BAD_LENGTH)
    return ftype, length, seq, ts


def pack_header(buf, ftype: int, length: int, seq: int, ts: int, offset: int = 0) -> None:
    HEADER.pack_into(buf, offset, MAGIC, VERSION, ftype, length, seq & 0xFFFFFFFF, ts)


def frame(ftype: int, payload: bytes = b"", seq: int = 0, ts: int = 0) -> bytes:
    """A whole frame as bytes (for clients and tests; the server packs in place)."""
    return HEADER.pack(MAGIC, VERSION, ftype, len(payload), seq & 0xFFFFFFFF, ts) + payload


def error_frame(code: int, message: str) -> bytes:
    body = ERROR_HEAD.pack(code) + message.encode("utf-8", "replace")[: MAX_PAYLOAD - ERROR_HEAD.size]
    return frame(ERROR, body)
