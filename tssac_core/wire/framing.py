"""Finding the MAVLink frames in one UDP datagram: one scanner for both ends of our links.

The SITL vehicles (``sim_vehicles.link.mavlink_io``) and the companions (``mavlink_bridge.link.connection``) split every
datagram with :func:`scan_frames` and only then verify (signing) and decode (pymavlink) each frame, so the
same bytes give the same frames on both sides. A candidate frame is a start byte (0xFD MAVLink 2, 0xFE
MAVLink 1) whose header gives a length that fits in the datagram, whose message id the dialect knows and
whose CRC (with the message's CRC_EXTRA) matches. Anything else is not a frame: the scan goes on from the
next byte, so a valid frame behind a garbage header in the same datagram is still found, and a frame of an
unknown message id is dropped (its CRC cannot be checked, so neither can its length: it may be garbage
claiming a long frame over the next real one). UDP keeps datagram boundaries: a frame cut off by the end of
its datagram is dropped, never joined to the next datagram.

Checked frames become message objects through :class:`FrameDecoder`: the objects pymavlink's ``MAVLink.decode``
makes of them, without checking the CRC a second time. Sending, both ends pack their frames with
:class:`FramePacker`: the bytes pymavlink's ``MAVLink_message.pack`` makes (MAVLink 2, trailing zeros of the payload
cut, CRC with CRC_EXTRA, signed with the fields of pymavlink's ``MAVLinkSigning``), without the header object, the
frame buffer and the CRC object pymavlink builds for every frame: on the lockstep's critical path each of them is
paid once per frame and step.

Pure standard library: the caller passes the dialect (its CRC_EXTRA table and the CRC-16/MCRF4XX function),
so tssac_core imports no pymavlink.
"""

from __future__ import annotations

import hashlib
import operator
import struct
from collections.abc import Callable, Mapping, Sequence
from dataclasses import dataclass, field
from typing import Any, Protocol

__all__ = ["Dialect", "FrameDecoder", "FramePacker", "Scan", "SigningState", "crc16_mcrf4xx", "scan_frames"]

MAGIC_V1, MAGIC_V2 = 0xFE, 0xFD
HEADER_LEN_V1, HEADER_LEN_V2 = 6, 10
"""Bytes before the payload, start byte included."""
SIGNATURE_LEN = 13
IFLAG_SIGNED = 0x01
_START_BYTES = (bytes((MAGIC_V2,)), bytes((MAGIC_V1,)))
_MAGICS = frozenset((MAGIC_V2, MAGIC_V1))
_ONE_BYTE = tuple(bytes((b,)) for b in range(256))
"""``bytes((b,))`` for every byte value, made once."""


def _crc16_table() -> tuple[int, ...]:
    table = []
    for byte in range(256):
        crc = byte
        for _ in range(8):
            crc = (crc >> 1) ^ 0x8408 if crc & 1 else crc >> 1
        table.append(crc)
    return tuple(table)


_CRC16_TABLE = _crc16_table()


def crc16_mcrf4xx_python(data: bytes) -> int:
    """CRC-16/MCRF4XX (MAVLink's X.25 checksum: reflected 0x1021, initial 0xFFFF), one table look-up per byte."""
    crc = 0xFFFF
    for b in data:
        crc = (crc >> 8) ^ _CRC16_TABLE[(crc ^ b) & 0xFF]
    return crc


try:  # the C implementation pymavlink itself uses when it is installed (fastcrc, optional)
    from fastcrc import crc16 as _fastcrc16

    def crc16_mcrf4xx(data: bytes) -> int:
        """CRC-16/MCRF4XX of ``data`` (fastcrc's C code; :func:`crc16_mcrf4xx_python` without it)."""
        return int(_fastcrc16.mcrf4xx(data, 0xFFFF))

except ImportError:  # pragma: no cover - depends on the environment
    crc16_mcrf4xx = crc16_mcrf4xx_python


@dataclass(frozen=True)
class Dialect:
    """What framing needs from a MAVLink dialect."""

    crc_extras: Mapping[int, int]
    """Message id -> CRC_EXTRA, for every message the dialect knows."""
    crc16: Callable[[bytes], int]
    """CRC-16/MCRF4XX of a byte string (MAVLink's X.25 checksum)."""

    @classmethod
    def of_messages(cls, message_classes: Mapping[int, Any]) -> Dialect:
        """The dialect of a generated message table (message id -> a class with ``crc_extra``, e.g. pymavlink's
        ``ardupilotmega.mavlink_map``), with MAVLink's checksum: how both ends build theirs."""
        return cls({mid: int(c.crc_extra) for mid, c in message_classes.items()}, crc16_mcrf4xx)


@dataclass
class Scan:
    """The frames of one datagram, in order, and what was not a frame."""

    frames: list[bytes] = field(default_factory=list)
    garbage_bytes: int = 0
    """Bytes skipped outside any candidate frame (including impossible headers)."""
    truncated: int = 0
    """Candidate frames cut off by the end of the datagram."""
    unknown_id: int = 0
    """Candidate frames of a message id the dialect does not know."""
    bad_crc: int = 0
    consumed: int = 0
    """Bytes of ``data`` the scan is done with: all of them, or (``stream``) up to the frame still arriving."""


def scan_frames(data: bytes, dialect: Dialect, *, stream: bool = False) -> Scan:
    """Every frame in ``data`` whose header, message id and CRC check out (module docstring).

    ``stream``: ``data`` is the start of a byte stream, not a datagram (:mod:`tssac_core.wire.stream_framing`): a
    candidate frame cut off by its end is not dropped but ends the scan, and :attr:`Scan.consumed` says where it
    starts (the rest of it may come with the next bytes)."""
    out = Scan()
    crc_extras = dialect.crc_extras
    i, n = 0, len(data)
    while i < n:
        if data[i] not in _MAGICS:
            j = _next_start(data, i + 1)
            out.garbage_bytes += j - i
            i = j
            continue
        size = frame_size(data, i)
        if size is None:  # impossible header: not a frame start
            out.garbage_bytes += 1
            i += 1
            continue
        if i + size > n:
            if stream:
                break
            out.truncated += 1
            i += 1  # it may be garbage that happens to hold a start byte: rescan past it
            continue
        frame = data[i : i + size]
        crc_extra = crc_extras.get(message_id(frame))
        if crc_extra is None:
            out.unknown_id += 1
            i += 1
            continue
        if not _crc_ok(frame, crc_extra, dialect):
            out.bad_crc += 1
            i += 1
            continue
        out.frames.append(frame)
        i += size
    out.consumed = i
    return out


def frame_size(data: bytes, i: int) -> int | None:
    """Total length of the frame starting at ``data[i]`` from its header, None if the header is impossible.

    A header cut off by the end of the datagram reports the minimum length, so it counts as truncated.
    """
    if data[i] == MAGIC_V2:
        if i + 3 > len(data):
            return HEADER_LEN_V2 + 2
        length, incompat = data[i + 1], data[i + 2]
        if incompat & ~IFLAG_SIGNED:
            return None
        return HEADER_LEN_V2 + length + 2 + (SIGNATURE_LEN if incompat & IFLAG_SIGNED else 0)
    if i + 2 > len(data):
        return HEADER_LEN_V1 + 2
    return HEADER_LEN_V1 + data[i + 1] + 2


def message_id(frame: bytes) -> int:
    """The message id in a frame's header."""
    return frame[7] | (frame[8] << 8) | (frame[9] << 16) if frame[0] == MAGIC_V2 else frame[5]


def source(frame: bytes) -> tuple[int, int]:
    """The sender's (system id, component id) in a frame's header."""
    return (frame[5], frame[6]) if frame[0] == MAGIC_V2 else (frame[3], frame[4])


def _crc_ok(frame: bytes, crc_extra: int, dialect: Dialect) -> bool:
    """The frame's checksum (header after the start byte, payload, CRC_EXTRA) matches."""
    end = len(frame) - (SIGNATURE_LEN if frame[0] == MAGIC_V2 and frame[2] & IFLAG_SIGNED else 0)
    return dialect.crc16(bytes(frame[1 : end - 2]) + _ONE_BYTE[crc_extra]) == frame[end - 2] | (frame[end - 1] << 8)


def _next_start(data: bytes, start: int) -> int:
    """Index of the next MAVLink start byte at or after ``start`` (len(data) if none)."""
    found = [k for k in (data.find(b, start) for b in _START_BYTES) if k >= 0]
    return min(found) if found else len(data)


_HEADER_V2 = struct.Struct("<BBBBBBBHB")
_CRC = struct.Struct("<H")
_SIGNATURE_HEAD = struct.Struct("<BQ")


class SigningState(Protocol):
    """The outgoing fields of pymavlink's ``MAVLinkSigning`` (the packer advances ``timestamp`` as pymavlink does)."""

    secret_key: bytes | None
    link_id: int
    timestamp: int
    sign_outgoing: bool


class FramePacker:
    """Packs messages of a pymavlink dialect into MAVLink 2 frames, byte for byte as pymavlink does.

    Reads per message class what pymavlink's generated ``pack`` reads: ``unpacker`` (the payload's struct, fields in
    wire order), ``ordered_fieldnames`` with their ``lengths`` (numeric arrays are spread, one struct item per element;
    strings are packed from their raw bytes), ``crc_extra`` and ``id``. The payload's trailing zero bytes are cut (at
    least one byte stays), the checksum covers the header after its start byte, the payload and CRC_EXTRA, and a signed
    frame ends in link id, 6-byte timestamp and ``SHA-256(key + frame so far)[:6]``, after which the timestamp advances
    by one (``MAVLinkSigning.sign_packet``).

    A message is given either as a pymavlink object (:meth:`pack`) or, for a class whose fields are all scalars, as its
    class and field values (:meth:`pack_fields`), so that a sender of many small frames need not build the object.
    """

    def __init__(self, crc16: Callable[[bytes], int]) -> None:
        self._crc16 = crc16
        self._layouts: dict[type, _Layout] = {}
        self._key: bytes | None = None
        self._keyed: Any = None
        """SHA-256 with the key already absorbed (copied for every frame)."""

    def pack(self, msg: Any, seq: int, sysid: int, compid: int, signing: SigningState | None = None) -> bytes:
        """One frame of ``msg`` from (``sysid``, ``compid``) with sequence number ``seq``; signed if ``signing`` says
        ``sign_outgoing``."""
        layout = self._layouts.get(type(msg)) or self._layout(type(msg))
        return self._frame(layout, layout.items_of(msg), seq, sysid, compid, signing)

    def pack_fields(
        self, cls: type, fields: Sequence[Any], seq: int, sysid: int, compid: int, signing: SigningState | None = None
    ) -> bytes:
        """The frame :meth:`pack` makes of ``cls(*fields)``: ``fields`` in the constructor's order (the arguments of
        pymavlink's ``<message>_encode``). Only for classes without strings and arrays (ValueError otherwise)."""
        layout = self._layouts.get(cls) or self._layout(cls)
        order = layout.wire_order
        if order is None:
            raise ValueError(f"{getattr(cls, 'msgname', cls)} has string or array fields: pack the message object")
        items = fields if order == () else [fields[k] for k in order]
        return self._frame(layout, items, seq, sysid, compid, signing)

    def _layout(self, cls: Any) -> _Layout:
        layout = self._layouts[cls] = _Layout.of_class(cls)
        return layout

    def _frame(
        self, layout: _Layout, items: Sequence[Any], seq: int, sysid: int, compid: int, signing: SigningState | None
    ) -> bytes:
        payload = layout.payload.pack(*items)
        payload = payload.rstrip(b"\x00") or payload[:1]
        signed = signing is not None and signing.sign_outgoing
        frame = _HEADER_V2.pack(
            MAGIC_V2, len(payload), IFLAG_SIGNED if signed else 0, 0, seq, sysid, compid, layout.id_low, layout.id_high
        )
        frame += payload
        frame += _CRC.pack(self._crc16(frame[1:] + layout.crc_extra))
        if not signed:
            return frame
        assert signing is not None and signing.secret_key is not None
        frame += _SIGNATURE_HEAD.pack(signing.link_id, signing.timestamp)[:7]
        signing.timestamp += 1
        if signing.secret_key != self._key:
            self._key, self._keyed = signing.secret_key, hashlib.sha256(signing.secret_key)
        h = self._keyed.copy()
        h.update(frame)
        return frame + h.digest()[:6]


@dataclass(frozen=True)
class _Layout:
    """What :class:`FramePacker` reads of one message class, read once."""

    payload: struct.Struct
    crc_extra: bytes
    """CRC_EXTRA as the one byte the checksum ends with."""
    id_low: int
    """The message id's low 16 bits (header bytes 7 and 8)."""
    id_high: int
    """The message id's high byte (header byte 9)."""
    items_of: Callable[[Any], Sequence[Any]]
    """A message object's struct items in wire order (:func:`_field_getter`)."""
    wire_order: tuple[int, ...] | None
    """For each wire field, the index of its constructor argument (``()``: the same order); None if the class has
    strings or arrays."""

    @classmethod
    def of_class(cls, msg_class: Any) -> _Layout:
        flat = all(n == 1 for n in msg_class.lengths) and "char" not in msg_class.fieldtypes
        order: tuple[int, ...] | None = None
        if flat:
            names = list(msg_class.fieldnames)
            order = tuple(names.index(name) for name in msg_class.ordered_fieldnames)
            if order == tuple(range(len(names))):
                order = ()
        msg_id = int(msg_class.id)
        return cls(
            payload=msg_class.unpacker,
            crc_extra=bytes((msg_class.crc_extra,)),
            id_low=msg_id & 0xFFFF,
            id_high=msg_id >> 16,
            items_of=_field_getter(msg_class),
            wire_order=order,
        )


def _field_getter(cls: Any) -> Callable[[Any], Any]:
    """The struct items of a message in wire order: scalars as they are, strings as their raw bytes (pymavlink keeps
    them in ``_<name>_raw``), numeric arrays spread."""
    types = dict(zip(cls.fieldnames, cls.fieldtypes, strict=True))
    spec = [
        (f"_{name}_raw" if types[name] == "char" else name, n)
        for name, n in zip(cls.ordered_fieldnames, cls.lengths, strict=True)
    ]
    if all(n == 1 for _, n in spec):
        get = operator.attrgetter(*(name for name, _ in spec))
        return get if len(spec) > 1 else lambda msg: (get(msg),)

    def items(msg: Any) -> list[Any]:
        out: list[Any] = []
        for name, n in spec:
            value = getattr(msg, name)
            if n == 1:
                out.append(value)
            else:
                out.extend(value[k] for k in range(n))
        return out

    return items


class FrameDecoder:
    """Turns frames :func:`scan_frames` has checked into a pymavlink dialect's message objects, attribute for attribute
    what pymavlink's ``MAVLink.decode`` returns for them from a protocol object without a key (our receivers verify
    signatures themselves, before decoding).

    ``message_map`` is the dialect's ``mavlink_map`` (message id -> class) and ``header`` its ``MAVLink_header``. The
    CRC is not computed again and no signing counters are kept; the rest is pymavlink's decoding: the payload padded
    with the zeros MAVLink 2 cut off, unpacked in wire order, put back in the constructor's order (arrays as lists),
    strings stripped of trailing NULs, and the frame's buffer, payload, CRC and header set on the object. A frame of an
    id the map lacks raises KeyError.
    """

    def __init__(self, message_map: Mapping[int, Any], header: Callable[..., Any]) -> None:
        self._map = message_map
        self._header = header
        self._arguments: dict[type, Callable[[tuple[Any, ...]], list[Any]] | None] = {}
        """Per message class, what makes its constructor's arguments of the unpacked items; None: the items are."""

    def decode(self, frame: bytes) -> Any:
        if frame[0] == MAGIC_V2:
            header_len, incompat, compat = HEADER_LEN_V2, frame[2], frame[3]
            seq, sysid, compid = frame[4], frame[5], frame[6]
            msg_id = frame[7] | (frame[8] << 8) | (frame[9] << 16)
        else:
            header_len, incompat, compat = HEADER_LEN_V1, 0, 0
            seq, sysid, compid, msg_id = frame[2], frame[3], frame[4], frame[5]
        cls = self._map[msg_id]
        end = len(frame) - 2 - (SIGNATURE_LEN if incompat & IFLAG_SIGNED else 0)
        unpacker = cls.unpacker
        missing = unpacker.size - (end - header_len)
        if missing > 0:  # MAVLink 2 cut the payload's trailing zeros: put them back
            items = unpacker.unpack(frame[header_len:end] + bytes(missing))
        else:
            items = unpacker.unpack_from(frame, header_len)
        try:
            arguments = self._arguments[cls]
        except KeyError:
            arguments = self._arguments[cls] = _constructor_arguments(cls)
        msg = cls(*items) if arguments is None else cls(*arguments(items))
        buf = bytearray(frame)
        msg._msgbuf = buf
        msg._payload = buf[6:end]  # pymavlink's offset, for MAVLink 1 and 2 alike
        msg._crc = frame[end] | (frame[end + 1] << 8)
        msg._header = self._header(msg_id, incompat, compat, frame[1], seq, sysid, compid)
        return msg


def _constructor_arguments(cls: Any) -> Callable[[tuple[Any, ...]], list[Any]] | None:
    """Unpacked payload (wire order) -> constructor arguments: ``orders`` maps each argument to its wire field, numeric
    arrays become lists, strings lose their trailing NULs. None for a message of single numbers in wire order (the
    step-rate SYSTEM_TIME and LOCAL_POSITION_NED among them): its items are its arguments."""
    orders, lengths = list(cls.orders), list(cls.lengths)
    strings = [i for i, t in enumerate(cls.fieldtypes) if t == "char"]
    if not strings and orders == list(range(len(orders))) and sum(lengths) == len(lengths):
        return None
    if sum(lengths) == len(lengths):  # no arrays: one wire item per field
        picks = [(o, 1) for o in orders]
    else:
        starts = [sum(lengths[:k]) for k in range(len(lengths))]
        picks = [(starts[o], lengths[o]) for o in orders]

    def arguments(items: tuple[Any, ...]) -> list[Any]:
        out: list[Any] = []
        for start, n in picks:
            first = items[start]
            out.append(first if n == 1 or isinstance(first, bytes) else list(items[start : start + n]))
        for i in strings:
            if isinstance(out[i], bytes):
                out[i] = out[i].rstrip(b"\x00")
        return out

    return arguments
