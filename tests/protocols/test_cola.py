"""CoLa-A and CoLa-B, byte for byte: replies, errors, framing edge cases and LMDscandata telegrams.

The expected bytes are written out by hand from SICK's telegram listing
(docs/cola.md); the property tests read the encoder's telegrams back with a
decoder written here from the listing's field table, independent of
protocols.cola.values.
"""

from __future__ import annotations

import struct
import subprocess
import sys
from pathlib import Path
from dataclasses import dataclass

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from protocols.cola import ColaDevice, ColaUnit, UnitModel
from protocols.cola.framing import MAX_SCAN_TELEGRAM, ColaReader, Dialect, checksum, frame
from protocols.cola.values import hex_token_runs, hex_tokens

TIM = UnitModel("TiM5xx", "TiM5xx", "V3.10", "12345678", -450000, 2250000, {1500: (3333,)}, (1500, 3333), 1, 1.0)
LMS5 = UnitModel("LMS5xx", "LMS5xx", "V1.90", "1234", -50000, 1850000, {2500: (1667, 5000), 5000: (5000,)},
                 (2500, 5000), 5, 2.0)


@dataclass
class FakeScan:
    echoes: np.ndarray
    echo_intensities: np.ndarray
    time_s: float | None = None


class Source:
    """Beam i's echoes: 1000 + i, then 2000 + i (LMS5xx: beams with an even index have two)."""

    def __init__(self, model: UnitModel) -> None:
        self.model = model
        self.requests: list[tuple[float, dict]] = []

    def __call__(self, time_s: float, **request) -> FakeScan:
        self.requests.append((time_s, request))
        count = self.model.beam_count(request["resolution_ticks"])
        echoes = np.full((count, self.model.echoes), -1, np.int64)
        echoes[:, 0] = 1000 + np.arange(count)
        if self.model.echoes > 1:
            echoes[::2, 1] = 2000 + np.arange(0, count, 2)
        powers = np.where(echoes >= 0, 0x1234, -1)
        return FakeScan(echoes, powers, time_s)


def device(model: UnitModel = TIM) -> ColaDevice:
    return ColaDevice(Source(model), ColaUnit(model))


def ask(dev: ColaDevice, text: bytes, now: float = 1.0) -> bytes:
    return b"".join(output.data for output in dev.receive(b"\x02" + text + b"\x03", now))


def ask_b(dev: ColaDevice, payload: bytes, now: float = 1.0) -> bytes:
    return b"".join(output.data for output in dev.receive(frame(payload, Dialect.BINARY), now))


def b_frame(payload: bytes) -> bytes:
    xor = 0
    for byte in payload:
        xor ^= byte
    return b"\x02\x02\x02\x02" + struct.pack(">I", len(payload)) + payload + bytes([xor])


# -- replies, byte for byte ------------------------------------------------------


def test_cola_a_start_up_replies_byte_for_byte():
    dev = device()
    assert ask(dev, b"sMN SetAccessMode 03 F4724744") == b"\x02sAN SetAccessMode 1\x03"
    assert ask(dev, b"sMN SetAccessMode 03 12345678") == b"\x02sAN SetAccessMode 0\x03"
    assert ask(dev, b"sRN DeviceIdent") == b"\x02sRA DeviceIdent 6 TiM5xx 5 V3.10\x03"
    assert ask(dev, b"sRN SerialNumber") == b"\x02sRA SerialNumber 8 12345678\x03"
    assert ask(dev, b"sRN FirmwareVersion") == b"\x02sRA FirmwareVersion 5 V3.10\x03"
    assert ask(dev, b"sRN SCdevicestate") == b"\x02sRA SCdevicestate 1\x03"
    assert ask(dev, b"sRN LocationName") == b"\x02sRA LocationName B not defined\x03"
    assert ask(dev, b"sRN LMPscancfg") == b"\x02sRA LMPscancfg 5DC 1 D05 FFF92230 225510\x03"
    assert ask(dev, b"sMN mLMPsetscancfg +1500 +1 +3333 -450000 +2250000") == (
        b"\x02sAN mLMPsetscancfg 0 5DC 1 D05 FFF92230 225510\x03")
    assert ask(dev, b"sWN LMDscandatacfg 01 00 1 1 0 00 00 0 0 0 0 +1") == b"\x02sWA LMDscandatacfg\x03"
    assert ask(dev, b"sRN LMDscandatacfg") == b"\x02sRA LMDscandatacfg 1 0 1 1 0 0 0 0 0 0 0 1\x03"
    assert ask(dev, b"sMN LMCstartmeas") == b"\x02sAN LMCstartmeas 0\x03"
    assert ask(dev, b"sMN Run") == b"\x02sAN Run 1\x03"
    assert ask(dev, b"sEN LMDscandata 1") == b"\x02sEA LMDscandata 1\x03"
    assert ask(dev, b"sEN LMDscandata 0") == b"\x02sEA LMDscandata 0\x03"


def test_cola_b_replies_byte_for_byte():
    dev = device()
    assert ask_b(dev, b"sMN SetAccessMode \x03\xf4\x72\x47\x44") == b_frame(b"sAN SetAccessMode \x01")
    assert ask_b(dev, b"sRN LMPscancfg") == b_frame(
        b"sRA LMPscancfg \x00\x00\x05\xdc\x00\x01\x00\x00\x0d\x05\xff\xf9\x22\x30\x00\x22\x55\x10")
    assert ask_b(dev, b"sRN DeviceIdent") == b_frame(b"sRA DeviceIdent \x00\x06TiM5xx\x00\x05V3.10")
    assert ask_b(dev, b"sMN mLMPsetscancfg \x00\x00\x05\xdc\x00\x01\x00\x00\x13\x88\xff\xf9\x22\x30\x00\x22\x55\x10") == (
        b_frame(b"sAN mLMPsetscancfg \x02\x00\x00\x05\xdc\x00\x01\x00\x00\x0d\x05\xff\xf9\x22\x30\x00\x22\x55\x10"))
    assert ask_b(dev, b"sWN LMDscandatacfg \x01\x00\x00\x00\x00\x00\x00\x00\x00\x00\x00\x00\x01") == (
        b_frame(b"sWA LMDscandatacfg"))
    assert ask_b(dev, b"sRN NoSuchVariable") == b_frame(b"sFA \x00\x0b")


def test_start_up_filters_are_taken_like_the_unit_and_echo_settings_only_where_it_has_them():
    dev = device()
    ask(dev, b"sMN SetAccessMode 03 F4724744")
    assert ask(dev, b"sWN LFPmeanfilter 0 +3 0") == b"\x02sWA LFPmeanfilter\x03"
    assert ask(dev, b"sWN LFPparticle 0 +500") == b"\x02sWA LFPparticle\x03"
    assert ask(dev, b"sWN LFPparticle 0") == b"\x02sFA 8\x03"
    assert ask(dev, b"sWN FREchoFilter 2") == b"\x02sFA B\x03"  # a TiM5xx has one echo and no echo filter
    lms = device(LMS5)
    ask(lms, b"sMN SetAccessMode 03 F4724744")
    assert ask(lms, b"sWN FREchoFilter 2") == b"\x02sWA FREchoFilter\x03"
    assert ask(lms, b"sRN FREchoFilter") == b"\x02sRA FREchoFilter 2\x03"
    assert ask(lms, b"sWN MSsuppmode 1") == b"\x02sWA MSsuppmode\x03"
    assert lms.scan_request()["fog_filter"] is True  # the fog filter reaches the physics
    assert ask(lms, b"sWN FREchoFilter 3") == b"\x02sFA 4\x03"


def test_errors_are_the_units_sfa_codes():
    dev = device()
    assert ask(dev, b"sWN LMDscandatacfg 01 00 1 1 0 00 00 0 0 0 0 +1") == b"\x02sFA A\x03"  # not logged in
    assert ask(dev, b"sMN mLMPsetscancfg +1500 +1 +3333 -450000 +2250000") == b"\x02sFA 1\x03"
    assert ask(dev, b"sRN NoSuchVariable") == b"\x02sFA B\x03"
    assert ask(dev, b"xyz LMPscancfg") == b"\x02sFA C\x03"
    assert ask(dev, b"sRIO") == b"\x02sFA C\x03"
    ask(dev, b"sMN SetAccessMode 03 F4724744")
    assert ask(dev, b"sMN mLMPsetscancfg +1500 +1") == b"\x02sFA 8\x03"  # too few arguments
    assert ask(dev, b"sMN mLMPsetscancfg +15x0 +1 +3333 0 0") == b"\x02sFA 11\x03"
    for python_only in (b"+1_500", b"0x5DC", b"+\xef\xbc\x91500"):  # int() takes them; the unit's syntax does not
        assert ask(dev, b"sMN mLMPsetscancfg " + python_only + b" +1 +3333 0 0") == b"\x02sFA 11\x03"
    assert ask(dev, b"sEN LMDscandata 1FF") == b"\x02sFA 10\x03"
    assert ask(dev, b"sMN mLMPsetscancfg +2500 +1 +3333 0 0") == b"\x02sAN mLMPsetscancfg 1 5DC 1 D05 FFF92230 225510\x03"
    assert ask(dev, b"sWN LMDscandatacfg 02 00 1 1 0 00 00 0 0 0 0 +1") == b"\x02sFA 4\x03"  # a TiM has one echo


def test_settings_outlive_the_connection_until_reboot():
    unit = ColaUnit(LMS5)
    first = ColaDevice(Source(LMS5), unit)
    ask(first, b"sMN SetAccessMode 03 F4724744")
    assert ask(first, b"sMN mLMPsetscancfg +5000 +1 +5000 0 0") == b"\x02sAN mLMPsetscancfg 0 1388 1 1388 FFFF3CB0 1C3A90\x03"
    first.connection_lost()
    second = ColaDevice(Source(LMS5), unit)
    assert ask(second, b"sRN LMPscancfg") == b"\x02sRA LMPscancfg 1388 1 1388 FFFF3CB0 1C3A90\x03"
    assert ask(second, b"sMN mSCreboot") == b"\x02sFA 1\x03"  # the login went with the first connection
    ask(second, b"sMN SetAccessMode 03 F4724744")
    assert ask(second, b"sMN mSCreboot", 2.0) == b"\x02sAN mSCreboot\x03"
    assert ask(second, b"sRN LMPscancfg", 2.0) == b"\x02sRA LMPscancfg 9C4 1 1388 FFFF3CB0 1C3A90\x03"


# -- framing -----------------------------------------------------------------------


def test_a_new_device_builds_the_token_table_so_the_first_scan_telegram_does_not():
    """The u16 token table costs 15-70 ms to build: a device builds it when made (a fresh interpreter,
    where nothing built it yet), not when the first `sRN LMDscandata` is due."""
    program = (
        "import protocols.cola.values as values\n"
        "from tests.protocols.test_cola import device\n"
        "assert values._U16_TOKENS is None\n"
        "device()\n"
        "assert values._U16_TOKENS is not None\n"
    )
    result = subprocess.run([sys.executable, "-c", program], cwd=Path(__file__).parents[2], capture_output=True, text=True, timeout=60)
    assert result.returncode == 0, result.stderr[-2000:]


def test_framing_edge_cases():
    reader = ColaReader()
    assert reader.feed(b"\x00junk\x02sRN SCdev") == []
    assert [t.payload for t in reader.feed(b"icestate\x03\x00")] == [b"sRN SCdevicestate"]
    # a half telegram cut short by a new STX is dropped; the new one is read
    assert [t.payload for t in reader.feed(b"\x02sRN Foo\x02sRN Bar\x03")] == [b"sRN Bar"]
    good = b_frame(b"sRN LMPscancfg")
    bad = good[:-1] + bytes([good[-1] ^ 1])
    assert reader.feed(bad) == []  # wrong checksum: dropped, no answer
    assert [t.dialect for t in reader.feed(good[:5])] == []
    assert [t.dialect for t in reader.feed(good[5:])] == [Dialect.BINARY]
    huge = b"\x02\x02\x02\x02\xff\xff\xff\xff"
    assert [t.payload for t in reader.feed(huge + b"\x02sRN A\x03")] == [b"sRN A"]
    assert reader.dropped == 3
    flood = b"\x02" + b"x" * 20_000
    assert reader.feed(flood) == [] and [t.payload for t in reader.feed(b"\x02sRN B\x03")] == [b"sRN B"]


@pytest.mark.parametrize("pieces", [1, 40])
def test_a_cola_a_telegram_longer_than_the_limit_is_dropped_however_it_arrives(pieces: int) -> None:
    """Whole in one read or in slices: the limit is the telegram's length, not the read's."""
    reader = ColaReader()
    data = b"\x02sRN DeviceIdent" + b" " * 20_000 + b"\x03\x02sRN B\x03"
    size = -(-len(data) // pieces)
    telegrams = [t.payload for at in range(0, len(data), size) for t in reader.feed(data[at:at + size])]
    assert telegrams == [b"sRN B"] and reader.dropped == 1
    host = ColaReader(MAX_SCAN_TELEGRAM)  # a host reading the unit: its scans run to ~60 KB in CoLa-A
    assert [len(t.payload) for t in host.feed(data)] == [len(b"sRN DeviceIdent") + 20_000, 5]


def test_a_wrong_checksum_gets_no_answer():
    dev = device()
    good = frame(b"sRN SCdevicestate", Dialect.BINARY)
    assert dev.receive(good[:-1] + bytes([good[-1] ^ 0xFF]), 1.0) == []
    assert [o.data for o in dev.receive(good, 1.0)] == [b_frame(b"sRA SCdevicestate \x01")]


@given(st.binary(max_size=300))
@settings(max_examples=200, deadline=None)
def test_checksum_is_the_xor_of_the_payload(payload):
    xor = 0
    for byte in payload:
        xor ^= byte
    assert checksum(payload) == xor


@given(st.lists(st.integers(0, 2**32 - 1), max_size=50))
@settings(deadline=None)  # the first call builds the u16 token table (~0.1 s, longer on a busy machine)
def test_hex_tokens(values):
    assert hex_tokens(np.array(values, dtype=np.uint64)) == b"".join(f"{v:X} ".encode() for v in values)


@given(st.lists(st.lists(st.integers(0, 0xFFFF) | st.integers(0, 2**32 - 1), max_size=20), max_size=6),
       st.sampled_from([np.uint16, np.uint32, np.int64]))
@settings(deadline=None)
def test_hex_token_runs_are_each_arrays_tokens(arrays, dtype):
    arrays = [np.array(values, dtype=np.uint64).astype(dtype) if dtype is not np.uint16 or max(values, default=0) <= 0xFFFF
              else np.array(values, dtype=np.uint64) for values in arrays]
    assert hex_token_runs(arrays) == [" ".join(f"{v:X}" for v in values.tolist()).encode() for values in arrays]


# -- LMDscandata -------------------------------------------------------------------


def decode_scandata(payload: bytes, dialect: Dialect) -> dict:
    """The listing's field table, read back: an independent decoder."""
    head = payload.split(b" ", 2)
    assert head[1] == b"LMDscandata"
    if dialect is Dialect.ASCII:
        tokens = payload.split(b" ")[2:]
        position = 0

        def take(kind: str):
            nonlocal position
            token = tokens[position]
            position += 1
            if kind in ("raw",):
                return token.decode()
            if kind == "f32":
                return struct.unpack(">f", bytes.fromhex(token.decode()))[0]
            value = int(token, 16)
            if kind == "i32" and value >= 2**31:
                value -= 2**32
            return value

        def take_array(count: int, kind: str) -> list[int]:
            return [take(kind) for _ in range(count)]

        def take_text() -> str:
            nonlocal position
            length = int(tokens[position], 16)
            text = tokens[position + 1].decode()
            position += 2
            assert len(text) == length
            return text
    else:
        data = payload.split(b" ", 2)[2]
        offset = 0
        sizes = {"u8": ">B", "u16": ">H", "u32": ">I", "i32": ">i", "f32": ">f"}

        def take(kind: str):
            nonlocal offset
            if kind == "raw":
                text = data[offset:offset + 5].decode()
                offset += 5
                return text
            value = struct.unpack_from(sizes[kind], data, offset)[0]
            offset += struct.calcsize(sizes[kind])
            return value

        def take_array(count: int, kind: str) -> list[int]:
            return [take(kind) for _ in range(count)]

        def take_text() -> str:
            nonlocal offset
            length = struct.unpack_from(">H", data, offset)[0]
            offset += 2 + length
            return data[offset - length:offset].decode()

    fields = {}
    for name, kind in [("version", "u16"), ("device", "u16"), ("serial", "u32"), ("status1", "u8"), ("status2", "u8"),
                       ("telegram", "u16"), ("scan", "u16"), ("power_up_us", "u32"), ("transmission_us", "u32"),
                       ("in1", "u8"), ("in2", "u8"), ("out1", "u8"), ("out2", "u8"), ("reserved", "u16"),
                       ("frequency", "u32"), ("measurement_frequency", "u32"), ("encoders", "u16")]:
        fields[name] = take(kind)
    fields["encoder"] = [(take("u32"), take("u16")) for _ in range(fields["encoders"])]
    channels = {}
    for width in ("u16", "u8"):
        for _ in range(take("u16")):
            content, scale, offset_, start, step, count = (take("raw"), take("f32"), take("f32"), take("i32"),
                                                           take("u16"), take("u16"))
            channels[content] = (scale, offset_, start, step, take_array(count, width))
    fields["channels"] = channels
    fields["position"] = take("u16")
    fields["name"] = [take_text() for _ in range(take("u16"))]
    fields["comment"] = take("u16")
    fields["time"] = [tuple(take(kind) for kind in ("u16", "u8", "u8", "u8", "u8", "u8", "u32")) for _ in range(take("u16"))]
    fields["events"] = take("u16")
    return fields


def streamed(dev: ColaDevice, now: float) -> list[bytes]:
    return [o.data for o in dev.poll(now)]


@given(dialect=st.sampled_from([Dialect.ASCII, Dialect.BINARY]), echo_filter=st.sampled_from([0, 1, 2]),
       channels=st.integers(1, 31), rssi=st.booleans(), wide=st.booleans(),
       output=st.tuples(st.integers(-50000, 1850000), st.integers(-50000, 1850000)),
       encoder=st.booleans(), named=st.booleans(), clock=st.booleans())
@settings(max_examples=80, deadline=None)
def test_scandata_reads_back_field_by_field(dialect, echo_filter, channels, rssi, wide, output, encoder, named, clock):
    dev = device(LMS5)
    ask(dev, b"sMN SetAccessMode 03 F4724744", 0.0)
    ask(dev, b"sWN LMDscandatacfg %X 0 %d %d 0 %d 0 0 %d 0 %d +1" % (channels, rssi, wide, encoder, named, clock), 0.0)
    ask(dev, b"sWN FREchoFilter %d" % echo_filter, 0.0)
    start, stop = sorted(output)
    if start < stop:
        assert ask(dev, b"sWN LMPoutputRange 1 1388 %+d %+d" % (start, stop), 0.0) == b"\x02sWA LMPoutputRange\x03"
    else:
        start, stop = -50000, 1850000
    now = 0.5
    request = b"sRN LMDscandata"
    reply = ask(dev, request, now) if dialect is Dialect.ASCII else ask_b(dev, request, now)
    payload = reply[1:-1] if dialect is Dialect.ASCII else reply[8:-1]
    fields = decode_scandata(payload, dialect)
    index = int(now / 0.04 + 1e-9)
    assert fields["scan"] == index and fields["telegram"] == 1 and fields["serial"] == 1234
    assert fields["frequency"] == 2500 and fields["measurement_frequency"] == 180
    assert fields["transmission_us"] == 500_000
    assert fields["power_up_us"] == round((index * 0.04 - 0.04 * 190 / 360) * 1e6)
    first = int(np.ceil((start + 50000) / 5000 - 1e-9))
    last = int(np.floor((stop + 50000) / 5000 + 1e-9))
    beams = np.arange(first, last + 1)
    second = np.where(beams % 2 == 0, 2000 + beams, 0)
    expected = {0: [1000 + beams], 2: [np.where(beams % 2 == 0, second, 1000 + beams)],
                1: [1000 + beams, second, *[np.zeros_like(beams)] * 3]}[echo_filter]
    names = [f"DIST{k + 1}" for k in range(len(expected)) if echo_filter != 1 or channels >> k & 1]
    dist = {name: values for name, values in fields["channels"].items() if name.startswith("DIST")}
    assert list(dist) == names
    for name in names:
        scale, offset, start_angle, step, values = dist[name]
        assert (scale, offset, step) == (2.0, 0.0, 5000)
        assert start_angle == -50000 + first * 5000
        assert values == list(expected[int(name[4:]) - 1])
    rssi_channels = [name for name in fields["channels"] if name.startswith("RSSI")]
    assert rssi_channels == ([name.replace("DIST", "RSSI") for name in names] if rssi else [])
    for name in rssi_channels:
        values = fields["channels"][name][4]
        assert set(values) <= {0, 0x1234 if wide else 0xFF}
    assert fields["encoder"] == ([(0, 0)] if encoder else [])
    assert fields["name"] == (["LMS5xx"] if named else [])
    assert fields["time"] == ([(2000, 1, 1, 0, 0, 0, 500_000)] if clock else [])
    assert (fields["position"], fields["comment"], fields["events"]) == (0, 0, 0)


def test_streamed_telegrams_come_once_per_scan_in_the_dialect_asked():
    dev = device()
    assert [o.data for o in dev.receive(frame(b"sEN LMDscandata \x01", Dialect.BINARY), 0.01)] == [
        b_frame(b"sEA LMDscandata \x01")]
    assert dev.next_deadline() == 1 / 15
    assert streamed(dev, 0.05) == []
    telegrams = streamed(dev, 1 / 15)
    assert len(telegrams) == 1 and telegrams[0].startswith(b"\x02\x02\x02\x02") and b"sSN LMDscandata " in telegrams[0]
    fields = decode_scandata(telegrams[0][8:-1], Dialect.BINARY)
    assert fields["scan"] == 1 and fields["channels"]["DIST1"][4][:3] == [1000, 1001, 1002]
    assert streamed(dev, 0.1) == []
    late = [decode_scandata(data[8:-1], Dialect.BINARY)["scan"] for data in streamed(dev, 0.2)]
    assert late == [2, 3]  # a late wake-up sends the scans it missed
    far = [decode_scandata(data[8:-1], Dialect.BINARY)["scan"] for data in streamed(dev, 1.5)]
    assert far == list(range(16, 23))  # those of the last 0.5 s: further behind, the newest ones
    assert dev.next_deadline() == pytest.approx(23 / 15)
    dev.connection_lost()
    assert dev.next_deadline() is None


def test_a_source_that_hands_out_its_freshest_scan_gets_it_stamped_as_itself_and_sent_once():
    """A daemon that is behind hands a device the freshest scan it has, with that scan's own time."""
    source = Source(TIM)

    def behind(time_s: float, **request) -> FakeScan:
        scan = source(time_s, **request)
        scan.time_s = max(1 / 15, time_s - 2 / 15)  # two scans behind what was asked
        return scan

    dev = ColaDevice(behind, ColaUnit(TIM))
    dev.receive(frame(b"sEN LMDscandata \x01", Dialect.BINARY), 0.01)
    first = [decode_scandata(data[8:-1], Dialect.BINARY) for data in streamed(dev, 3 / 15 + 1e-6)]
    assert [(f["scan"], f["transmission_us"]) for f in first] == [(1, round(1e6 / 15))]  # 2 and 3 gave scan 1 again
    later = [decode_scandata(data[8:-1], Dialect.BINARY)["scan"] for data in streamed(dev, 5 / 15 + 1e-6)]
    assert later == [2, 3]


@pytest.mark.parametrize("change", [
    [b"sMN LMCstopmeas", b"sMN LMCstartmeas"],
    [b"sMN mLMPsetscancfg +5000 +1 +5000 -50000 +1850000"],
    [b"sWN MSsuppmode 1"],
], ids=["stop-start", "scancfg", "fog-filter"])
def test_a_stream_goes_on_after_the_scans_restart_counting(change):
    """New settings restart the unit's scan indices; a stream kept the old ones and sent nothing until
    the new count caught up (as long as the unit had run: 3 s of silence after 3 s of streaming)."""
    dev, other_port = device(LMS5), None
    unit = dev.unit
    dev.receive(b"\x02sEN LMDscandata 1\x03", 0.0)
    before = [decode_scandata(data[1:-1], Dialect.ASCII)["scan"] for data in streamed(dev, 3.0)]
    assert before and before[-1] == 75  # 25 Hz
    other_port = ColaDevice(Source(LMS5), unit)  # the command comes on the unit's other port
    other_port.receive(b"\x02sMN SetAccessMode 03 F4724744\x03", 3.01)
    for command in change:
        other_port.receive(b"\x02" + command + b"\x03", 3.01)
    period = unit.period_s
    assert dev.next_deadline() == pytest.approx(3.01 + period)
    after = [decode_scandata(data[1:-1], Dialect.ASCII)["scan"] for data in streamed(dev, 3.01 + 5 * period + 1e-6)]
    assert after == list(range(before[-1] + 1, before[-1] + 6))


def test_a_reboot_drops_both_ports_connections_after_its_answer_and_the_next_clients_count_from_one():
    """`mSCreboot` from one port: its answer, then the connection drops (nothing after it in the same read
    is answered); the other port's streaming client is dropped at its next scan; a client connecting
    after the reboot is served, its stream's scans counting from 1 (a real unit's network restarts)."""
    dev = device(LMS5)
    unit = dev.unit
    dev.receive(b"\x02sEN LMDscandata 1\x03", 0.0)
    assert streamed(dev, 1.0)
    other_port = ColaDevice(Source(LMS5), unit)
    other_port.receive(b"\x02sMN SetAccessMode 03 F4724744\x03", 1.01)
    outputs = other_port.receive(b"\x02sMN mSCreboot\x03\x02sRN LMPscancfg\x03", 1.01)
    assert [(o.data, o.hang_up) for o in outputs] == [(b"\x02sAN mSCreboot\x03", False), (b"", True)]
    assert [o.hang_up for o in dev.poll(1.01 + unit.period_s)] == [True]  # no scan after the reboot
    dev.connection_lost()  # the transport hung up: its session ends
    other_port.connection_lost()
    assert ask(other_port, b"sRN LMPscancfg", 1.5).startswith(b"\x02sRA LMPscancfg ")  # a new client: served
    dev.receive(b"\x02sEN LMDscandata 1\x03", 1.5)
    after = [decode_scandata(data[1:-1], Dialect.ASCII)["scan"] for data in streamed(dev, 1.5 + 3 * unit.period_s)]
    assert after[-3:] == [(1.5 - 1.01) // unit.period_s + k for k in (1, 2, 3)]  # counted from the reboot


@pytest.mark.parametrize(("start", "stop", "first_angle", "beams"), [
    (0, 900000, 0, 271), (-140000, 1500000, -140000, 493), (-450000, 2250000, -450000, 811), (1, 3333, 3333, 1),
])
def test_the_output_range_keeps_a_beam_lying_on_its_edge_at_a_third_of_a_degree(start, stop, first_angle, beams):
    """Beams at −45° + k/3°: 0° is beam 135, which a division by the rounded 3333 ticks put out of range."""
    dev = device()
    ask(dev, b"sMN SetAccessMode 03 F4724744", 0.0)
    assert ask(dev, b"sWN LMPoutputRange 1 D05 %+d %+d" % (start, stop), 0.0) == b"\x02sWA LMPoutputRange\x03"
    fields = decode_scandata(ask(dev, b"sRN LMDscandata", 0.5)[1:-1], Dialect.ASCII)
    _, _, start_angle, step, values = fields["channels"]["DIST1"]
    assert (start_angle, step, len(values)) == (first_angle, 3333, beams)
