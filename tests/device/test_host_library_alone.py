"""The host library (``hcard.device``) works without the reference device: a process in which
``hcard_device`` cannot be imported plays a card on a device served by another process over
USB/IP, writes the recording and says what happened. What needs a device simulated in this
process (``sim://``) says the reference device is missing instead."""

from __future__ import annotations

import subprocess
import sys

import pytest

from hcard.calibration.measurement import read_measurement
from tests.helpers.served_device import served_device

pytestmark = pytest.mark.wall_clock

CLIENT = r'''
import importlib.abc
import sys


class NoReferenceDevice(importlib.abc.MetaPathFinder):
    """As if the reference device were not installed."""

    def find_spec(self, name, path, target=None):
        if name == "hcard_device" or name.startswith("hcard_device."):
            raise ModuleNotFoundError(f"No module named {name!r}", name=name)
        return None


sys.meta_path.insert(0, NoReferenceDevice())
import warnings

from hcard import build
from hcard.device import UriError, open_device
from hcard.device.play import play
from hcard.device.play_summary import summary
from hcard.device.recording import write_recording
from hcard.track import straight_stroke

warnings.simplefilter("ignore")  # the reference device's plugins fail to load: reported there
uri, out = sys.argv[1], sys.argv[2]
try:
    open_device("sim://")
except UriError as exc:
    print("sim://:", exc)
card = build.card(81.0, 54.0, taxtel_mm=27.0, textures=[
    build.texture(1.0, channel="uv"), build.texture(0.5, channel="uv")],
    texture_index=[0, 1, 0, 1, 0, 1])
with open_device(uri) as driver:
    result = play(driver, card, straight_stroke((10.0, 20.0), (60.0, 0.0), 0.8))
print("rows", write_recording(result, out))
print("\n".join(summary(result)))
print("reference device modules:", sorted(m for m in sys.modules if m.startswith("hcard_device")))
'''


def test_play_and_record_without_the_reference_device_installed(tmp_path):
    out = tmp_path / "session.csv"
    with served_device() as served:
        run = subprocess.run([sys.executable, "-c", CLIENT, served.uri, str(out)],
                             capture_output=True, text=True, timeout=300)
    assert run.returncode == 0, run.stderr[-3000:]
    lines = run.stdout.splitlines()
    assert "reference device modules: []" in lines
    assert any(line.startswith("sim://:") and "no installed driver provides one" in line
               for line in lines), run.stdout
    rows = int(next(line.split()[1] for line in lines if line.startswith("rows ")))
    assert rows >= 700  # 0.8 s of STATE reports at 1 kHz, less the ones lost on a loaded host
    assert any(line.startswith("played ") for line in lines)
    recording = read_measurement(out)
    assert len(recording.t) == rows
    touching = recording.contact.astype(bool)
    assert touching.sum() > 0.5 * rows  # the finger the host sent reached the device
    # the device played the card: its target is 1 on one taxtel column and 0.5 on the next
    target = recording.device["target_uv"][touching]
    assert target.min() < 0.6 and target.max() > 0.95
