"""A session of any length is recorded in bounded memory: the reports are kept packed at their
wire widths (58 bytes each), the recording is written block by block, and the file is the same
as the one built whole."""

from __future__ import annotations

import dataclasses
import itertools
import tracemalloc

import numpy as np
import pytest

from hcard import build
from hcard.calibration.measurement import read_measurement, write_measurement
from hcard.calibration.rendering import rendering_error
from hcard.device import open_device
from hcard.device import recording as recording_module
from hcard.device.play import play
from hcard.device.play_result import PlayResult
from hcard.device.protocol import State
from hcard.device.protocol.base import I16
from hcard.device.recording import force_recording, recording, write_recording
from hcard.device.state_log import STATE_ROW, StateLog
from hcard.track import make_track

pytestmark = pytest.mark.wall_clock

CARD = build.card(20.0, 10.0, taxtel_mm=10.0, textures=[
    build.texture(1.0, channel="uv", name="plain"), build.texture(0.5, channel="uv", name="slip")],
    texture_index=[0, 1], title="step")


def strokes(count: int) -> object:
    """``count`` strokes 2 mm <-> 18 mm at 40 mm/s, 100 Hz samples, 0.5 N."""
    there = np.linspace(2.0, 18.0, 41)
    one = np.concatenate([there, there[::-1][1:]])
    x = np.concatenate([one] + [one[1:]] * (count - 1))
    t = np.arange(x.size) * 0.01
    return make_track(t, x, np.full(x.size, 5.0), 0.5, True)


@pytest.fixture(scope="module")
def session() -> PlayResult:
    with open_device("sim://evita?seed=4") as driver:
        return play(driver, CARD, strokes(6))


def random_states(rng: np.random.Generator, count: int) -> list[State]:
    """Reports with every field drawn over its whole range (the edges included)."""
    names = [f.name for f in dataclasses.fields(State)]
    states = []
    for k in range(count):
        values = {}
        for name in names:
            if name == "corner_forces_mn":
                values[name] = tuple(int(v) for v in rng.integers(I16[0], I16[1] + 1, 4))
                continue
            low, high = State.RANGES[name]
            edge = k % 3
            values[name] = low if edge == 0 else high if edge == 1 else int(
                rng.integers(low, high + 1))
        states.append(State(**values))
    return states


@pytest.mark.parametrize("seed", [0, 1])
def test_the_log_gives_back_every_field_of_every_report(seed):
    rng = np.random.default_rng(seed)
    states = random_states(rng, StateLog.CHUNK_REPORTS + 123)  # past one packed chunk
    log = StateLog()
    log.extend(states[:100])
    first = log[99]  # read while reports are still arriving
    log.extend(states[100:])
    assert first == states[99]
    assert list(log) == states
    assert log[-1] == states[-1] and log[4090:4100] == states[4090:4100]
    assert len(log) == len(states)
    expected_faults = 0
    for state in states:
        expected_faults |= state.faults
    assert log.faults_seen == expected_faults
    assert STATE_ROW.itemsize == State.size() - 1 == 58  # the wire report without its ID
    assert log.nbytes == 58 * len(states)
    np.testing.assert_array_equal(log.field("echo_age_us"), [s.echo_age_us for s in states])


def unwrapped_by_hand(stamps: list[int]) -> list[float]:
    """Device times from the first, s, unwrapping the u32 microsecond stamps one by one."""
    out, total = [0.0], 0
    for before, after in itertools.pairwise(stamps):
        total += (after - before) % (1 << 32)
        out.append(total * 1e-6)
    return out


def test_a_recording_written_in_blocks_is_the_recording_built_whole(session, tmp_path,
                                                                     monkeypatch):
    # the device clock wraps inside the session and one report arrives twice, both at a
    # block boundary, where the blocks must carry the clock and the repeat between them
    states = list(session.states)
    shift = (1 << 32) - states[500].timestamp_us - 500  # wraps 0.5 ms after report 500
    states = [dataclasses.replace(s, timestamp_us=(s.timestamp_us + shift) % (1 << 32))
              for s in states]
    states.insert(601, states[600])
    result = dataclasses.replace(session, states=states)
    whole = recording(result)
    monkeypatch.setattr(recording_module, "BLOCK_REPORTS", 601 // 3 + 1)  # ends at 602
    rows = write_recording(result, tmp_path / "blocks.csv")
    write_measurement(whole, tmp_path / "whole.csv")
    assert (tmp_path / "blocks.csv").read_bytes() == (tmp_path / "whole.csv").read_bytes()
    assert rows == len(states) - 1  # the repeated report is left out once (rule MF7)
    stamps = [s.timestamp_us for s in states]
    expected = unwrapped_by_hand(stamps)
    expected = [t for k, t in enumerate(expected) if k == 0 or t > expected[k - 1]]
    back = read_measurement(tmp_path / "blocks.csv")
    np.testing.assert_array_equal(back.t, expected)
    assert back.t[500] < back.t[502] < 1.0  # the wrap did not jump the time


def test_the_summary_error_from_the_force_columns_is_the_recordings(session):
    full = rendering_error(recording(session))
    lean = rendering_error(force_recording(session))
    assert full.patches >= 5
    assert lean == full


def long_result(session: PlayResult, repeats: int) -> PlayResult:
    """``session``'s reports ``repeats`` times over, one after another on the device clock."""
    states = list(session.states)
    span = states[-1].timestamp_us - states[0].timestamp_us + 1000
    log = StateLog()
    for k in range(repeats):
        log.extend(dataclasses.replace(s, timestamp_us=(s.timestamp_us + k * span) % (1 << 32),
                                       sequence=(s.sequence + k * len(states)) % 65536)
                   for s in states)
    return dataclasses.replace(session, states=log)


def write_peak(result: PlayResult, path) -> int:
    """Peak bytes allocated (tracemalloc) while ``result`` is written to ``path``, its packed
    reports joined into one array beforehand (they are held whatever is written)."""
    result.states.rows()
    tracemalloc.start()
    try:
        write_recording(result, path)
        return tracemalloc.get_traced_memory()[1]
    finally:
        tracemalloc.stop()


def test_writing_a_recording_holds_one_block_whatever_its_length(session, tmp_path):
    short, long = long_result(session, 4), long_result(session, 16)
    assert len(long.states) > 4 * recording_module.BLOCK_REPORTS
    short_peak = write_peak(short, tmp_path / "short.csv")
    long_peak = write_peak(long, tmp_path / "long.csv")
    # 4x the reports, not 4x the memory: the packed reports (58 B each, already held) plus one
    # block of rows being formatted
    assert long_peak < 1.3 * short_peak, (short_peak, long_peak)
    assert long_peak < 40e6
    assert len(read_measurement(tmp_path / "long.csv")) == len(long.states)


def test_sessions_over_usbip_are_recorded_in_blocks_twice_against_one_server(tmp_path,
                                                                           monkeypatch):
    """Over USB/IP from a server in another process, in real time, two sessions in a row:
    the packed log holds the reports the driver decoded (every field), and the recording written
    in blocks is the one built whole."""
    from hcard.device import recording as recording_module
    from tests.helpers.realtime import in_real_time, kept_run
    from tests.helpers.served_device import served_device

    monkeypatch.setattr(recording_module, "BLOCK_REPORTS", 500)  # several blocks per session
    seen: list[list[State]] = []
    with served_device() as served, open_device(served.uri) as driver:
        original = driver.collect_until

        def collect_until(deadline_s: float) -> list[State]:
            got = original(deadline_s)
            seen[-1].extend(got)
            return got

        driver.collect_until = collect_until

        def one_session() -> PlayResult:  # run again while the machine did not keep real time
            seen.append([])
            with kept_run(seen[-1]):
                result = play(driver, CARD, strokes(2))
                # what the driver decoded while the session streamed, field by field (it also
                # collects reports before START, which the recording leaves out)
                first = seen[-1].index(result.states[0])
                assert list(result.states) == seen[-1][first:first + len(result.states)]
                assert len(result.states) == pytest.approx(1000 * result.duration_s, rel=0.05)
            return result

        for session in range(2):
            result = in_real_time(one_session, f"recorded session {session + 1} over usbip")
            rows = write_recording(result, tmp_path / f"blocks{session}.csv")
            write_measurement(recording(result), tmp_path / f"whole{session}.csv")
            assert (tmp_path / f"blocks{session}.csv").read_bytes() == \
                (tmp_path / f"whole{session}.csv").read_bytes()
            assert rows > 2 * 500
            back = read_measurement(tmp_path / f"blocks{session}.csv")
            assert np.all(np.diff(back.t) > 0)
            assert back.stroke.max() >= 3  # the two strokes there and back, from the track
