"""Serve the hcard reference device over USB/IP: ``python -m hcard_device.usb.server``.

The firmware runs in real time on its own thread (:meth:`Firmware.run_realtime`), which after
each step hands its new STATE reports to the interrupt IN queue of every connection (the pump,
:meth:`HcardHID.pump`; a separate pump thread that polled every 0.5 ms cost 15 % of a core and
left the server's threads, which share one interpreter lock, no spare time on a 2-core machine:
a streamed queue ran dry in 10-156 of ~800 reports, 0-1 with the pump on the firmware's
thread, ``bench/bench_stream_feed.py``); the USB/IP listener (``TCP_NODELAY`` on every socket)
serves URBs on per-connection threads; the card of a COMMIT is checked in a worker process
(:class:`~hcard_device.card_check.ProcessChecker`, at most 20 s) while the device runs on. Any
Linux host can then ``usbip attach -r HOST -b 1-1`` and get a ``/dev/hidrawN``. SIGINT and
SIGTERM stop it cleanly: the firmware thread ends and is joined, the listener and
every connection are closed (hosts see the device vanish), the check worker ends, and the
process exits with status 0.

Several clients may import the device at the same time, as several processes may open one
hidraw node (spec rules PN10, PN12-PN14): each gets every STATE report in its own bounded
queue; the connection whose START or TAKE_OVER began the live session owns it, and the
state-changing reports of the others are refused while it lasts; endpoint halts are per
connection. Every client is isolated from the others' behaviour by bounds (spec section 13):

========================================  ==========  =========================================
bound                                     value       past it
========================================  ==========  =========================================
connections served at once                8           a further one is closed when accepted
connections accepted per second           50          the others wait in the listen backlog
STATE reports queued per connection       32          the oldest is dropped (counted, PT5)
interrupt-IN URBs parked per connection   64          the connection is closed
OUT transfer length                       4096 B      the connection is closed, unread
interrupt-OUT reports per connection      1000 /s     further URBs wait (64 pass at once)
IN transfer length                        65535 B     the connection is closed
answers waiting for a non-reading client  64 KiB      the connection is closed
control transfers behind a slow one       4           the connection is closed
import handshake                          2 s         the connection is closed
check of one COMMIT (worker process)      20 s        worker killed; upload FAILED, INVALID_CARD
========================================  ==========  =========================================

No thread waits for a client: answers are written with non-blocking sends, and whatever a
socket does not take waits in the connection's own bounded buffer. Each close is logged on
stderr with its reason (refused connections: one line per second at most).

Options: ``--host`` (default 127.0.0.1), ``--port`` (default 3240; 0 picks a free port),
``--device evita|coupled``, ``--seed``. The first line on stdout is
``serving <variant> at usbip://HOST:PORT/1-1`` once the port is bound (tests wait for it).

A device is a machine of its own; this one shares a computer. Before it starts its threads the
server asks the operating system to run them ahead of ordinary processes
(:func:`raise_priority`: round-robin real-time scheduling where permitted, else a lower nice
value, else nothing), so that a loaded computer delays its real-time loop less. When it still
falls behind, the reports it produced late say so (fault REALTIME_LAG, rule PI4).
"""

from __future__ import annotations

import argparse
import contextlib
import os
import signal
import sys
import threading
import time
from collections.abc import Callable, Iterator, Mapping
from types import FrameType, TracebackType
from typing import Any

import usbip

from hcard.device import in_process
from hcard.device.priority import REALTIME_PRIORITY
from hcard.device.transports.usbip_connect import DEFAULT_BUSID, DEFAULT_HOST, DEFAULT_PORT
from hcard_device.card_check import CHECK_TIMEOUT_S, Checker, InlineChecker, ProcessChecker
from hcard_device.usb.device import DEFAULT_IN_QUEUE, PRODUCTS, HcardHID, build_usb_device
from hcard_device.usb.server_log import DEFAULT_LOG, ServerLog
from hcard_device.usb.transport import MAX_CONNECTIONS, BoundedLoopback, NoDelayUSBIP

SWITCH_INTERVAL_S = 0.0002
"""GIL switch interval of the server process, s (Python's default is 5 ms)."""
JOIN_TIMEOUT_S = 2.0
"""Longest wait for a thread to end on stop, s."""
NICE_INCREMENT = -10
"""Nice increment asked for when real-time scheduling is not permitted: ten steps give the
server about nine times the CPU share of an ordinary process (each step is ~1.25x)."""


def raise_priority() -> str:
    """Ask the OS to run this thread, and every thread it starts from now on (they inherit
    it), ahead of ordinary processes: ``SCHED_RR`` at :data:`REALTIME_PRIORITY` where permitted
    (root, or CAP_SYS_NICE), else nice :data:`NICE_INCREMENT`, else nothing (an unprivileged
    user; EPERM is not an error). The loops it protects sleep between steps (the firmware every
    :data:`~hcard_device.firmware.REALTIME_PERIOD_S`), so they never hold a CPU; the kernel
    also keeps 5 % of every CPU for ordinary processes whatever real-time threads do
    (``sched_rt_runtime_us``). Returns what was granted, for the banner. A caller that goes on
    after serving uses :func:`raised_priority`, which gives the priority back."""
    try:
        os.sched_setscheduler(0, os.SCHED_RR, os.sched_param(REALTIME_PRIORITY))
        return f"SCHED_RR {REALTIME_PRIORITY}"
    except (AttributeError, OSError):
        pass
    try:
        return f"nice {os.nice(NICE_INCREMENT)}"
    except OSError:
        return f"nice {os.nice(0)} (no higher priority permitted)"


@contextlib.contextmanager
def raised_priority() -> Iterator[str]:
    """:func:`raise_priority` for the block, and the calling thread's scheduling policy, its
    priority and its nice value as they were afterwards, however the block ends. ``serve``
    runs in the calling process (``hcard device serve`` in a test's process, through click's
    runner): without this, a serve that returned (a busy port) left that process's main thread
    at ``SCHED_RR``, and everything it started later (``hcard play`` processes, servers)
    inherited it: two real-time processes of one priority on two cores take turns in 100 ms
    slices, and a host starved that long trips the device's watchdog (found in CI)."""
    policy = os.sched_getscheduler(0)
    param = os.sched_getparam(0)
    nice = os.getpriority(os.PRIO_PROCESS, 0)
    try:
        yield raise_priority()
    finally:
        with contextlib.suppress(OSError):
            os.sched_setscheduler(0, policy, param)
        with contextlib.suppress(OSError):
            os.setpriority(os.PRIO_PROCESS, 0, nice)


def make_firmware(variant: str, seed: int = 0,
                  effects: Mapping[str, Mapping[str, float]] | None = None, *,
                  ambient_pressure_pa: float | None = None) -> Any:
    """A :class:`~hcard_device.firmware.Firmware` on a fresh simulation of ``variant``, with
    the physical ``effects`` hidden in its hardware (:mod:`hcard_device.sim.hidden`), in air at
    ``ambient_pressure_pa`` (Pa; None: one atmosphere).

    Raises:
        ValueError: an unknown variant, or an effect it cannot have
            (:class:`~hcard_device.sim.hidden.HiddenEffectError`).
    """
    from dataclasses import replace

    from hcard_device.firmware import Firmware
    from hcard_device.profiles import variant_config
    from hcard_device.sim import DeviceSimulation
    from hcard_device.sim.hidden import HiddenPhysics, resolve
    from hcard_device.sim.models import device_profile

    if variant not in PRODUCTS:
        raise ValueError(f"unknown device {variant!r}; known: {', '.join(PRODUCTS)}")
    config = variant_config(variant)
    if ambient_pressure_pa is not None:
        config = replace(config, ambient_pressure_pa=ambient_pressure_pa)
    hidden = HiddenPhysics(device_profile(config), resolve(variant, effects),
                           frame_rate_hz=config.frame_rate_hz,
                           ambient_pressure_pa=config.ambient_pressure_pa)
    return Firmware(DeviceSimulation(config, seed=seed, hidden=hidden))


class DeviceServer:
    """The device, its firmware thread (which also pumps its STATE reports to the connections)
    and its USB/IP listener.

    Args:
        variant: ``evita`` or ``coupled``.
        host, port: where to listen (port 0: a free one, see :attr:`port`).
        seed: seed of the simulation's noise.
        loopback: serve on in-process socket pairs (:class:`BoundedLoopback`) instead of TCP.
        nodelay: ``TCP_NODELAY`` on the served sockets (benchmarks turn it off).
        in_queue: STATE reports each connection's IN queue holds before dropping the oldest.
        effects: physical effects hidden in the hardware (:mod:`hcard_device.sim.hidden`:
            name -> parameter values), checked here.
        ambient_pressure_pa: the air pressure around the plate, Pa (None: one atmosphere).
        firmware_factory: builds the firmware instead of :func:`make_firmware` (negative
            controls of the conformance suite serve a deliberately faulty one).
        max_connections: connections served at once.
        check_in_process: check the cards of COMMITs in a worker process (the default), else
            in the committing connection's thread (still outside the firmware's lock).
        log: the server's log (default: stderr, through a writer thread that never blocks
            the server, at most 20 lines a second: :mod:`~hcard_device.usb.server_log`).

    Several clients may import the device at once, each isolated from the others by the
    bounds of the module docstring (spec rules PN10, PN12-PN14,
    :class:`~hcard_device.usb.device.ConnectionView`).
    """


    def __init__(self, variant: str = "evita", *, host: str = DEFAULT_HOST,
                 port: int = DEFAULT_PORT, seed: int = 0, loopback: bool = False,
                 nodelay: bool = True, in_queue: int = DEFAULT_IN_QUEUE,
                 effects: Mapping[str, Mapping[str, float]] | None = None,
                 ambient_pressure_pa: float | None = None,
                 firmware_factory: Callable[[], Any] | None = None,
                 max_connections: int = MAX_CONNECTIONS, check_in_process: bool = True,
                 log: Callable[[str], None] = DEFAULT_LOG) -> None:
        from hcard_device.sim.hidden import resolve

        if variant not in PRODUCTS:
            raise ValueError(f"unknown device {variant!r}; known: {', '.join(PRODUCTS)}")
        self.effects = resolve(variant, effects)
        self.ambient_pressure_pa = ambient_pressure_pa
        self.variant = variant
        self.host = host
        self.seed = seed
        self.loopback = loopback
        self.log = log
        self.transport: Any = (
            BoundedLoopback(max_connections=max_connections, log=log) if loopback
            else NoDelayUSBIP(host, port, nodelay=nodelay, max_connections=max_connections,
                              log=log))
        self.check_in_process = check_in_process
        self.checker: Checker | None = None
        self.in_queue = in_queue
        self.firmware_factory = firmware_factory
        self.firmware: Any = None
        self.interface: HcardHID | None = None
        self.usb_device: usbip.USBDevice | None = None
        self._stop = threading.Event()
        self._threads: list[threading.Thread] = []
        self.thread_errors: list[BaseException] = []

    @property
    def port(self) -> int:
        """The TCP port served (0 for a loopback server)."""
        return 0 if self.loopback else int(self.transport.port)

    @property
    def uri(self) -> str:
        """The URI a host driver opens."""
        if self.loopback:
            return f"usbip://loopback?device={self.variant}&seed={self.seed}"
        return f"usbip://{self.host}:{self.port}/{DEFAULT_BUSID}"

    def start(self) -> DeviceServer:
        """Build the firmware and the USB device, start the threads, bind and serve.

        Raises:
            OSError: the address cannot be bound.
        """
        self.firmware = (self.firmware_factory() if self.firmware_factory is not None
                         else make_firmware(self.variant, self.seed, self.effects,
                                            ambient_pressure_pa=self.ambient_pressure_pa))
        self.checker = (ProcessChecker(CHECK_TIMEOUT_S, log=self.log).start()
                        if self.check_in_process else InlineChecker())
        self.firmware.checker = self.checker
        self.usb_device, self.interface = build_usb_device(self.firmware, self.variant,
                                                           in_queue=self.in_queue)
        self.usb_device.plug(via=self.transport)
        in_process.note_serving(self, True)
        thread = threading.Thread(target=self._run_firmware, name="hcard-firmware", daemon=True)
        thread.start()
        self._threads.append(thread)
        return self

    def _run_firmware(self) -> None:
        interface = self.interface
        assert interface is not None
        try:
            self.firmware.run_realtime(self._stop, after_step=interface.pump)
        except BaseException as exc:  # reported by stop(); the device must not die silently
            self.thread_errors.append(exc)
            self._stop.set()

    @property
    def stopped(self) -> bool:
        """True once :meth:`stop` was called or a device thread failed."""
        return self._stop.is_set()

    def wait(self, timeout_s: float | None = None) -> bool:
        """Block until the server stops (or ``timeout_s`` passes); True when stopped."""
        return self._stop.wait(timeout_s)

    def request_stop(self) -> None:
        """Ask the server to stop (safe from a signal handler); :meth:`stop` finishes it."""
        self._stop.set()

    def stop(self) -> None:
        """Stop the firmware, close every connection, unplug (idempotent)."""
        self._stop.set()
        for thread in self._threads:
            thread.join(JOIN_TIMEOUT_S)
        self._threads.clear()
        if self.usb_device is not None:
            self.usb_device.unplug()
            self.usb_device = None
        if self.checker is not None:
            self.checker.close()
            self.checker = None
        in_process.note_serving(self, False)

    def __enter__(self) -> DeviceServer:
        return self.start() if self.usb_device is None else self

    def __exit__(self, exc_type: type[BaseException] | None, exc: BaseException | None,
                 tb: TracebackType | None) -> None:
        self.stop()


def _print(message: str, error: bool = False) -> None:
    print(message, file=sys.stderr if error else sys.stdout, flush=True)


def serve(variant: str = "evita", host: str = DEFAULT_HOST, port: int = DEFAULT_PORT,
          seed: int = 0, *, echo: Callable[[str, bool], None] = _print,
          effects: Mapping[str, Mapping[str, float]] | None = None,
          ambient_pressure_pa: float | None = None) -> int:
    """Serve until SIGINT or SIGTERM; returns the exit status (0 on a clean stop).

    ``echo(message, error)`` prints a line (to stderr when ``error``), flushed at once;
    ``effects`` are hidden in the hardware and never named on the wire or in the banner;
    ``ambient_pressure_pa``: the air around the plate, Pa (None: one atmosphere).
    """
    # The firmware thread computes for up to a millisecond at a time; with the default 5 ms
    # GIL switch interval the USB/IP threads would wait that long to answer a URB.
    switch_interval = sys.getswitchinterval()
    sys.setswitchinterval(SWITCH_INTERVAL_S)
    try:
        with raised_priority() as priority:  # before any thread starts: they inherit it
            return _serve(variant, host, port, seed, echo, effects, priority,
                          ambient_pressure_pa)
    finally:
        sys.setswitchinterval(switch_interval)


def _serve(variant: str, host: str, port: int, seed: int, echo: Callable[[str, bool], None],
           effects: Mapping[str, Mapping[str, float]] | None, priority: str,
           ambient_pressure_pa: float | None = None) -> int:
    """The body of :func:`serve`, at the priority it was granted (``priority``, for the
    banner)."""
    try:
        server = DeviceServer(variant, host=host, port=port, seed=seed, effects=effects,
                              ambient_pressure_pa=ambient_pressure_pa)
    except ValueError as exc:
        echo(f"error: {exc}", True)
        return 1
    try:
        server.start()
    except OSError as exc:
        echo(f"error: cannot serve on {host}:{port} ({exc.strerror or exc})", True)
        return 1

    def on_signal(signum: int, _frame: FrameType | None) -> None:
        server.request_stop()

    previous = {sig: signal.signal(sig, on_signal) for sig in (signal.SIGINT, signal.SIGTERM)}
    try:
        port_option = "" if server.port == DEFAULT_PORT else f"--tcp-port {server.port} "
        echo(f"serving {variant} at {server.uri} (attach: usbip {port_option}attach -r {host} "
             f"-b {DEFAULT_BUSID}); scheduling {priority}; Ctrl-C stops", False)
        started = time.monotonic()
        while not server.wait(0.5):
            pass
    finally:
        server.stop()
        for sig, handler in previous.items():
            signal.signal(sig, handler)
    if isinstance(server.log, ServerLog):
        server.log.drain()  # the lines of the last closes, before the final ones
    if server.thread_errors:
        echo(f"error: the device stopped: {server.thread_errors[0]!r}", True)
        return 1
    echo(f"stopped after {time.monotonic() - started:.1f} s", False)
    return 0


def main(argv: list[str] | None = None) -> int:
    """``python -m hcard_device.usb.server``; returns the exit status."""
    parser = argparse.ArgumentParser(prog="python -m hcard_device.usb.server",
                                     description=__doc__.splitlines()[0])
    parser.add_argument("--host", default=DEFAULT_HOST, help="address to listen on")
    parser.add_argument("--port", type=int, default=DEFAULT_PORT, help="TCP port (0: any)")
    parser.add_argument("--device", choices=sorted(PRODUCTS), default="evita")
    parser.add_argument("--seed", type=int, default=0, help="seed of the simulation noise")
    parser.add_argument("--effect", action="append", default=[], metavar="NAME",
                        help="hide a physical effect in the hardware (repeatable)")
    parser.add_argument("--effect-param", action="append", default=[],
                        metavar="EFFECT.PARAM=VALUE", help="a hidden effect's parameter")
    parser.add_argument("--ambient-pressure", default=None, metavar="PRESSURE",
                        help="air pressure around the plate (default one atmosphere)")
    args = parser.parse_args(argv)
    from hcard.device.uri import ambient_pressure
    from hcard_device.sim.hidden import HiddenEffectError, parse_assignments

    try:
        effects = parse_assignments(args.effect, args.effect_param)
        pressure = (None if args.ambient_pressure is None
                    else ambient_pressure(args.ambient_pressure))
    except (HiddenEffectError, ValueError) as exc:
        parser.error(str(exc))
    return serve(args.device, args.host, args.port, args.seed, effects=effects,
                 ambient_pressure_pa=pressure)


if __name__ == "__main__":
    raise SystemExit(main())
