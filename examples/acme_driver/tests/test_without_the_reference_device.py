"""The driver needs hcard's host library, not its reference device: in a process where
``hcard_device`` cannot be imported, acme:// plays a card and the conformance suite's device
checks judge it."""

from __future__ import annotations

import subprocess
import sys

CLIENT = r'''
import importlib.abc
import sys
import warnings


class NoReferenceDevice(importlib.abc.MetaPathFinder):
    """As if hcard's reference device were not installed."""

    def find_spec(self, name, path, target=None):
        if name == "hcard_device" or name.startswith("hcard_device."):
            raise ModuleNotFoundError(f"No module named {name!r}", name=name)
        return None


sys.meta_path.insert(0, NoReferenceDevice())
warnings.simplefilter("ignore")  # the reference device's plugins fail to load
from hcard import build
from hcard.device import open_device
from hcard.device.play import play
from hcard.track import straight_stroke
from hcard_conformance.context import Context
from hcard_conformance.registry import all_checks

card = build.card(120.0, 80.0, taxtel_mm=40.0, textures=[build.texture(0.6, channel="uv")])
with open_device("acme://tx1?seed=4") as driver:
    result = play(driver, card, straight_stroke((20.0, 40.0), (60.0, 0.0), 0.5))
print("reports", len(result.states))
ctx = Context.for_driver("acme://tx1?seed=4")
for check in all_checks(["device"]):
    if check.name in ("device.friction", "device.safety"):
        for r in check.run(ctx):
            print(check.name, r.case, "PASS" if r.passed else "FAIL")
print("reference device modules:", sorted(m for m in sys.modules if m.startswith("hcard_device")))
'''


def test_play_and_conformance_without_the_reference_device() -> None:
    run = subprocess.run([sys.executable, "-c", CLIENT], capture_output=True, text=True,
                         timeout=600)
    assert run.returncode == 0, run.stderr[-3000:]
    lines = run.stdout.splitlines()
    assert int(lines[0].split()[1]) >= 500          # 0.5 s at 1 kHz, and the tail
    verdicts = [line for line in lines if line.startswith("device.")]
    assert len(verdicts) == 6 and all(line.endswith("PASS") for line in verdicts), lines
    assert lines[-1] == "reference device modules: []"
