"""The NMEA fast path (formats.nmea.decode_fast, used by `imutool capture serial --protocol nmea`) against the
full path (parse_sentence + decode): same values for every line it accepts, under every checksum policy, and the
same capture output (raw log, CSV rows, counts by kind) as the original line-by-line capture loop.

Lines: hypothesis-generated sentences from the repo's NMEA writers and from random fields, corrupted variants
(flipped / deleted characters, truncation, missing or lower-case checksum, emptied fields, stray whitespace),
and every line of the real gpsd and Signal K logs.
"""

from __future__ import annotations

import itertools
import math
from pathlib import Path

import numpy as np
import pytest
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

from formats import nmea
from imutool.capture.runtime import StopFlag
from imutool.capture.serial_capture import NMEA_COLUMNS, _split_text, capture_nmea

POLICIES = ("require", "accept-missing", "ignore")
FAST_TYPES = ("HDT", "HDM", "THS", "ROT", "HDG", "XDR", "HRM", "PASHR", "RMC", "VTG", "PSTI")


# -- oracle: the capture's original per-line logic --------------------------------------------------------------
def _exact(values: dict) -> dict:
    """Values compared bit for bit (repr round-trips a float exactly and keeps the sign of zero)."""
    return {k: repr(v) for k, v in values.items()}


def full_outcome(line: str, policy: str) -> tuple:
    """What the capture loop did with one received line before the fast path existed."""
    text = line.strip()
    if not text:
        return ("blank",)
    try:
        sentence = nmea.parse_sentence(text, checksum_policy=policy)
    except Exception as e:
        return ("error", type(e).__name__)
    try:
        values = nmea.decode(sentence)
    except Exception as e:
        return ("frame", f"decode {type(e).__name__}")
    return ("values", _exact(values))


def assert_equivalent(line: str) -> bool:
    """decode_fast accepts only lines the full path decodes, to the same values under every policy.
    Returns whether the fast path took the line."""
    fast = nmea.decode_fast(line.strip())
    if fast is None:
        return False
    for policy in POLICIES:
        assert full_outcome(line, policy) == ("values", _exact(fast)), (line, policy)
    return True


def _split_lines_oracle(buf: bytearray, data: bytes) -> list[bytes]:
    """The capture's original byte-level line splitter (lines decoded one by one afterwards)."""
    buf.extend(data)
    out = []
    while True:
        i = buf.find(b"\n")
        if i < 0:
            if len(buf) > 8192:
                out.append(bytes(buf))
                buf.clear()
            return out
        out.append(bytes(buf[:i]))
        del buf[: i + 1]


# -- generated lines ------------------------------------------------------------------------------------------
_NUM = st.one_of(st.none(), st.floats(-400.0, 400.0, allow_nan=False), st.integers(-999, 999))
_FIELD_CHARS = "0123456789.-+eEinfaAVTDMNWSKR _"
_FIELD = st.one_of(
    st.sampled_from(
        [
            "",
            "A",
            "V",
            "T",
            "M",
            "N",
            "E",
            "W",
            "D",
            "K",
            "ROLL",
            "PTCH",
            "HEEL",
            "TRIM",
            "PITCH",
            " 1.5",
            "1.5 ",
            "inf",
            "nan",
            "1e3",
            "-.5",
            "5.",
            "1_0",
            "036",
            "123456.78",
            "120000",
        ]
    ),
    st.text(_FIELD_CHARS, max_size=8),
    st.floats(-1e6, 1e6, allow_nan=False).map(repr),
)


def _frame(address: str, fields: list[str]) -> str:
    body = ",".join([address] + fields)
    return f"${body}*{nmea.checksum(body)}"


@st.composite
def writer_sentences(draw) -> str:
    """A sentence from one of the repo's writers (valid by construction)."""
    kind = draw(
        st.sampled_from(["HDT", "THS", "HDG", "ROT", "XDR", "XDRG", "HRM", "PASHR", "HDM", "RMC", "VTG", "PSTI"])
    )
    v = [draw(_NUM) for _ in range(5)]
    f = [None if x is None else float(x) for x in v]
    if kind == "HDT":
        return nmea.hdt_sentence(f[0])
    if kind == "THS":
        return nmea.ths_sentence(f[0], mode=draw(st.sampled_from(list(nmea.THS_MODES))))
    if kind == "HDG":
        return nmea.hdg_sentence(f[0], f[1], f[2], talker=draw(st.sampled_from(["HC", "24", "II"])))
    if kind == "ROT":
        return nmea.rot_sentence(f[0], valid=draw(st.booleans()))
    if kind == "XDR":
        return nmea.xdr_roll_pitch(
            f[0],
            f[1],
            roll_id=draw(st.sampled_from(["ROLL", "HEEL", "Roll"])),
            pitch_id=draw(st.sampled_from(["PTCH", "PITCH", "TRIM", "FOO"])),
            roll_sign=draw(st.sampled_from([1, -1])),
        )
    if kind == "XDRG":  # any groups, including non-angle ones and odd units
        groups = draw(
            st.lists(
                st.tuples(
                    st.sampled_from(["A", "D", "C", "P", ""]),
                    _NUM,
                    st.sampled_from(["D", "M", "C", "", "B"]),
                    st.sampled_from(["ROLL", "PTCH", "HEEL", "AIRTEMP", "Heel Angle"]),
                ),
                min_size=1,
                max_size=3,
            )
        )
        return nmea.xdr_sentence([(a, None if b is None else float(b), c, d) for a, b, c, d in groups])
    if kind == "HRM":
        return nmea.hrm_sentence(f[0], f[1], f[2], f[3], valid=draw(st.booleans()), peak_port_deg=f[4])
    if kind == "PASHR":
        return nmea.pashr_sentence(draw(st.floats(0, 86399)), f[0], f[1], f[2], f[3])
    if kind == "HDM":
        return nmea.format_sentence("HC", "HDM", [f[0], "M"], [1, None])
    if kind == "RMC":
        return nmea.format_sentence(
            "GP",
            "RMC",
            [
                "120000.00",
                draw(st.sampled_from("AV")),
                "",
                "",
                "",
                "",
                f[0],
                f[1],
                "211126",
                "",
                "",
                draw(st.sampled_from("ADN")),
            ],
        )
    if kind == "VTG":
        return nmea.format_sentence(
            "GP", "VTG", [f[0], "T", "", "M", f[1], "N", f[2], "K", draw(st.sampled_from("ADN"))]
        )
    return nmea.format_sentence(
        "P", "STI", ["036", "120000.00", "211126", f[0], f[1], f[2], draw(st.sampled_from("ANF"))]
    )


@st.composite
def random_sentences(draw) -> str:
    """Any address and fields with a correct checksum: exercises field parsing and the decoders' checks."""
    talker = draw(st.sampled_from(["HE", "YX", "II", "GP", "24", "P", "he", "H$", "H"]))
    fmt = draw(st.sampled_from(list(FAST_TYPES) + ["ASHR", "STI", "GGA", "ZZZ", "HD", "HDTX"]))
    if talker == "P":
        fmt = draw(st.sampled_from(["ASHR", "STI", "HDT", "XYZ"]))
    fields = draw(st.lists(_FIELD, max_size=14))
    return _frame(talker + fmt, fields)


@st.composite
def corrupted(draw, base) -> str:
    """A sentence damaged in one way; body damage is re-checksummed half of the time (a device that sends
    garbage with a valid checksum), so the decoders' checks are reached, not only the checksum test."""
    s = draw(base)
    how = draw(
        st.sampled_from(
            [
                "none",
                "flip",
                "delete",
                "truncate",
                "insert",
                "empty_field",
                "no_checksum",
                "lower_checksum",
                "whitespace",
                "bang",
            ]
        )
    )
    body, tail = s[1:-3], s[-3:]
    n = len(body)
    if how == "flip":
        i = draw(st.integers(0, n - 1))
        c = draw(st.sampled_from(list("0123456789ABCDEF.,-*$!AVTMEWXn \t") + ["\ufffd", "\x7f", "\x00"]))
        body = body[:i] + c + body[i + 1 :]
    elif how == "delete":
        i = draw(st.integers(0, n - 1))
        body = body[:i] + body[i + 1 :]
    elif how == "truncate":
        body = body[: draw(st.integers(0, n))]
    elif how == "insert":
        i = draw(st.integers(0, n))
        body = (
            body[:i]
            + draw(st.sampled_from(["$", "*", ",", "*00", "GPGGA,1", ",,", "nan", "inf", "1e400", "_"]))
            + body[i:]
        )
    elif how == "empty_field":
        parts = body.split(",")
        parts[draw(st.integers(0, len(parts) - 1))] = ""
        body = ",".join(parts)
    elif how == "no_checksum":
        return s[:-3]
    elif how == "lower_checksum":
        return s[:-2] + s[-2:].lower()
    elif how == "whitespace":
        return draw(st.sampled_from([" ", "\t", "\r", ""])) + s + draw(st.sampled_from([" ", "\r", "\t", ""]))
    elif how == "bang":
        return "!" + s[1:]
    else:
        return s
    if draw(st.booleans()):
        return _frame(body, []) if body else "$*00"
    return "$" + body + tail


ANY_LINE = st.one_of(corrupted(writer_sentences()), corrupted(random_sentences()))


@settings(max_examples=400, deadline=None, suppress_health_check=[HealthCheck.too_slow])
@given(writer_sentences())
def test_fast_path_takes_every_clean_writer_sentence(line):
    fast = nmea.decode_fast(line)
    full = full_outcome(line, "require")
    if full[0] == "values":  # a clean sentence is taken by the fast path unless XDR notes a problem
        problems = nmea.decode_checked(line)[1]
        assert (fast is None) == bool(problems), line
    assert_equivalent(line)


@pytest.mark.slow
@settings(max_examples=1500, deadline=None, suppress_health_check=[HealthCheck.too_slow])
@given(ANY_LINE)
def test_fast_path_equals_full_path_on_corrupted_and_random_lines(line):
    assert_equivalent(line)


def test_fast_path_examples():
    assert nmea.decode_fast("$HEHDT,123.4,T*2B") == {"heading_true": 123.4}
    assert nmea.decode_fast("$HEHDT,123.4,T*2b") is None  # lower-case checksum: the full path decides
    assert nmea.decode_fast("$HEHDT,123.4,T*2C") is None  # bad checksum
    assert nmea.decode_fast("$HEHDT,123.4,T") is None  # missing checksum (a policy question)
    assert nmea.decode_fast(" $HEHDT,123.4,T*2B") is None  # not stripped
    assert nmea.decode_fast(_frame("HEHDT", ["abc", "T"])) is None  # NmeaFieldError in the full path
    assert nmea.decode_fast(_frame("GPGSV", ["1", "1", "00"])) is None  # unsupported type
    assert nmea.decode_fast(_frame("HEHDT", ["", "T"])) == {}  # a frame without a value: no CSV row
    assert nmea.decode_fast(_frame("YXXDR", ["A", "1.5", "D", "ROLL"]), {"ROLL": "-pitch"}) == {"pitch": -1.5}
    for line in ["$HEHDT,123.4,T*2B", _frame("HEHDT", ["abc", "T"]), _frame("24HDG", ["182.1", "0", "E", "", ""])]:
        assert_equivalent(line)


EDIT_BASES = [
    "HEHDT,123.4,T",
    "HCHDM,12.5,M",
    "HCHDG,120.3,1.2,E,3.4,W",
    "HCHDG,120.3,,,3.4,W",
    "TIROT,-3.2,A",
    "TIROT,3,V",
    "HETHS,123.4,A",
    "HETHS,5,V",
    "HETHS,,E",
    "YXXDR,A,-1.5,D,PTCH,A,3.2,D,ROLL",
    "YXXDR,A,2,,HEEL,C,10,C,AIR",
    "IIHRM,1.5,8.0,3.0,4.0,A,5.0,6.0,120000,21,11",
    "PASHR,120000.000,12.00,T,1.00,-2.00,0.30,,,,1,0",
    "GPRMC,120000.00,A,,,,,5.5,271.2,211126,,,A",
    "GPVTG,271.2,T,,M,5.5,N,10.2,K,A",
    "PSTI,036,120000,211126,1,2,3,A",
    "HEHDT,nan,T",
    "HEHDT,inf,T",
    "HEHDT, ,T",
    "HEHDT,1e2,T",
    "HEHDT,-0.0,T",
    "HETHS,12,AA",
]
EDIT_CHARS = list("\t\x7f\x00\ufffd$!*, AVXTNMEWD-.09enif_+") + ["", "\r\n"]


def test_every_single_character_edit_of_clean_sentences():
    """Exhaustive: every one-character substitution, insertion and deletion in the body of a clean sentence of
    each type, re-checksummed, so that only the framing and field checks can tell the lines apart."""
    taken = 0
    for base in EDIT_BASES:
        assert_equivalent(_frame(base, []))
        for i in range(len(base) + 1):
            for c in EDIT_CHARS:
                for body in {base[:i] + c + base[i + 1 :], base[:i] + c + base[i:]}:
                    taken += assert_equivalent(_frame(body, []) if body else "$*00")
    assert taken > 5000


def test_real_logs_fast_equals_full(shared):
    """Every line of the real gpsd and Signal K logs (as received, and from its first '$'/'!')."""
    files = [
        shared("nmea_gpsd", n)
        for n in (
            "bundg_zeus_9.log",
            "hemi.log",
            "pypilot.log",
            "rst39.log",
            "saab-r4.log",
            "skytraq-PX1172RH_DS.log",
            "tnt-revolution.log",
        )
    ]
    files += [shared("nmea_signalk", n) for n in ("gofree-merrimac.log", "n2kd-183-merrimac.log")]
    taken = checked = 0
    for p in files:
        for line in Path(p).read_text(encoding="latin-1").splitlines():
            starts = [i for i in (line.find("$"), line.find("!")) if i >= 0]
            for variant in {line, line[min(starts) :]} if starts else {line}:
                checked += 1
                taken += assert_equivalent(variant)
    assert checked > 13000 and taken > 2000  # the fast path is really exercised on real sentences


# -- the capture loop: batching, raw log, rows and counts ------------------------------------------------------
@settings(max_examples=200, deadline=None)
@given(
    st.lists(st.binary(max_size=300) | st.sampled_from([b"\n", b"\r\n", b"$HEHDT,1,T*0F\r\n", b"\xff\n"]), max_size=20),
    st.integers(0, 9000),
)
def test_split_text_gives_the_original_lines(chunks, long_len):
    chunks = chunks + [b"x" * long_len, b"\n"]
    b_old, b_new = bytearray(), bytearray()
    for c in chunks:
        old = [ln.decode("ascii", "replace") for ln in _split_lines_oracle(b_old, c)]
        assert _split_text(b_new, c) == old
        assert bytes(b_new) == bytes(b_old)


class _FakePort:
    """Serves pre-cut chunks as a serial port would; sets the stop flag when they are used up."""

    def __init__(self, chunks: list[bytes], stop: StopFlag):
        self.chunks, self.stop, self.pending = list(chunks), stop, b""

    def read(self, n: int) -> bytes:
        if not self.pending:
            if not self.chunks:
                self.stop.stop = True
                return b""
            self.pending = self.chunks.pop(0)
        out, self.pending = self.pending[:n], self.pending[n:]
        return out

    @property
    def in_waiting(self) -> int:
        return len(self.pending)

    def close(self) -> None:
        pass


def _capture(tmp: Path, chunks: list[bytes], policy: str) -> tuple[dict, list[str], list[list[float]]]:
    stop = StopFlag()
    summary = capture_nmea(
        "fake",
        4800,
        str(tmp / "o.csv"),
        status_s=None,
        quiet=True,
        checksum_policy=policy,
        opener=lambda port, baud: _FakePort(chunks, stop),
        stop=stop,
        force=True,
    )
    raw = (tmp / "o.nmea").read_bytes().decode("utf-8").split("\n")[:-1]  # a stray CR stays inside its line
    rows = []
    for ln in (tmp / "o.csv").read_text().splitlines():
        if ln and not ln.startswith("#") and not ln.startswith("time,"):
            rows.append([float(x) if x else math.nan for x in ln.split(",")])
    return summary, raw, rows


def _expected(stream: bytes, chunks: list[bytes], policy: str) -> tuple[dict, list[str], list[list[float]]]:
    """Counts, raw-log lines (without stamp) and CSV value cells the original per-line capture produced."""
    buf = bytearray()
    lines = [ln.decode("ascii", "replace") for c in chunks for ln in _split_lines_oracle(buf, c)]
    kinds: dict[str, int] = {}
    frames = 0
    rows = []
    for ln in lines:
        out = full_outcome(ln, policy)
        if out[0] == "error":
            kinds[out[1]] = kinds.get(out[1], 0) + 1
        elif out[0] == "frame":
            frames += 1
            kinds[out[1]] = kinds.get(out[1], 0) + 1
        elif out[0] == "values":
            frames += 1
            cells = [math.nan] * len(NMEA_COLUMNS)
            for k, v in out[1].items():
                if k in NMEA_COLUMNS:
                    cells[NMEA_COLUMNS.index(k)] = float(v)
            if not all(math.isnan(c) for c in cells):
                rows.append(cells)
    counts = {"lines": len(lines), "frames": frames, "errors": sum(kinds.values()), "error_kinds": kinds}
    return counts, [ln.rstrip() for ln in lines], rows


_RUNS = itertools.count()


def _stream(data: st.DataObject) -> bytes:
    lines = data.draw(st.lists(ANY_LINE | st.sampled_from(["", "  ", "garbage", "\x00\x01"]), min_size=1, max_size=60))
    ends = data.draw(st.lists(st.sampled_from(["\r\n", "\n"]), min_size=len(lines), max_size=len(lines)))
    return "".join(a + b for a, b in zip(lines, ends, strict=True)).encode("latin-1", "replace")


@pytest.mark.parametrize("policy", [POLICIES[0], *(pytest.param(p, marks=pytest.mark.slow) for p in POLICIES[1:])])
@settings(max_examples=15, deadline=None, suppress_health_check=[HealthCheck.function_scoped_fixture])
@given(data=st.data())
def test_capture_output_equals_original_loop(tmp_path, monkeypatch, policy, data):
    """Random chunking of a corrupted stream: counts by kind, raw log and CSV rows as the original loop gave,
    with the fast path and with it switched off."""
    stream = _stream(data)
    cuts = sorted(data.draw(st.lists(st.integers(1, max(1, len(stream) - 1)), max_size=6)))
    chunks = [stream[a:b] for a, b in zip([0] + cuts, cuts + [len(stream)], strict=True) if stream[a:b]]
    counts, raw_lines, rows = _expected(stream, chunks, policy)
    results = []
    for fast in (True, False):
        with monkeypatch.context() as m:
            if not fast:
                m.setattr(nmea, "decode_fast", lambda line, xdr_map=None: None)
            d = tmp_path / f"run{next(_RUNS)}"
            summary, raw, got_rows = _capture(d, chunks, policy)
        assert {k: summary[k] for k in counts} == counts
        assert [ln[28:] for ln in raw] == raw_lines  # '<ISO UTC stamp> <line as received>'
        assert all(ln[26:28] == "Z " for ln in raw)
        assert summary["rows"] == len(rows) == len(got_rows)
        np.testing.assert_array_equal(
            np.array(got_rows).reshape(-1, 2 + len(NMEA_COLUMNS))[:, 2:], np.array(rows).reshape(-1, len(NMEA_COLUMNS))
        )
        results.append((summary["lines"], summary["frames"], summary["error_kinds"], raw_lines, got_rows))
    assert results[0][:4] == results[1][:4]
