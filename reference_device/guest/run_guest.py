"""Boot the guest tier: a QEMU guest (software emulation, TCG) running the Debian kernel, which
attaches a USB-HID device served on the host's loopback over USB/IP and drives it from the host's
own Python through /dev/hidraw0.

    python3 reference_device/guest/run_guest.py [--mode hcard|echo|probe] [--timeout 240]

Steps: start the device server on 127.0.0.1:<free port> as a separate process; boot
`qemu-system-x86_64 -accel tcg` with build/guest's kernel and initramfs, QEMU user networking (the
guest reaches the host's 127.0.0.1 as 10.0.2.2) and the host root read-only over 9p; stream the
serial console to a log file; parse the payload's `hcard-guest: RESULT {json}` line; always stop
QEMU and the server.  Prints one JSON summary line on stdout; exits 0 when the payload passed, 1
when it failed (log tail on stderr), 2 on a bad argument, 3 when the guest tier is not installed.

Install first with `bash reference_device/guest/install.sh` (see README.md next to this file).
"""

from __future__ import annotations

import argparse
import json
import os
import queue
import shutil
import signal
import socket
import subprocess
import sys
import threading
import time
from collections.abc import Sequence
from pathlib import Path
from typing import IO, Any

HERE = Path(__file__).resolve().parent
REPO = HERE.parents[1]
MARKER = "hcard-guest: RESULT "
INIT_MARKER = "hcard-guest: init at"
FAIL_MARKER = "hcard-guest: FAIL "
QEMU = "qemu-system-x86_64"
EXIT_NOT_INSTALLED = 3
INSTALL_HINT = "run `bash reference_device/guest/install.sh` (as root) to install the guest tier"
# The guest mounts its own proc/sys/dev over these and a tmpfs over /run, hiding the host's.
HIDDEN_IN_GUEST = ("/proc", "/sys", "/dev", "/run")


def cache_dir() -> Path:
    return Path(os.environ.get("HCARD_GUEST_DIR") or REPO / "build" / "guest")


def find_kernel(cache: Path) -> Path | None:
    kernels = sorted((cache / "kernel" / "current" / "boot").glob("vmlinuz-*"))
    return kernels[-1] if kernels else None


def missing_parts(cache: Path | None = None) -> list[str]:
    """What of the guest tier is not installed (empty when it is ready to boot)."""
    cache = cache or cache_dir()
    missing = []
    if shutil.which(QEMU) is None:
        missing.append(f"{QEMU} (package qemu-system-x86)")
    if shutil.which("usbip") is None and not Path("/usr/sbin/usbip").exists():
        missing.append("usbip (package usbip)")
    if find_kernel(cache) is None:
        missing.append(f"the guest kernel in {cache}/kernel/current")
    if not (cache / "initramfs.cpio.gz").is_file():
        missing.append(f"the initramfs {cache}/initramfs.cpio.gz")
    return missing


def free_port() -> int:
    with socket.socket(socket.AF_INET, socket.SOCK_STREAM) as sock:
        sock.bind(("127.0.0.1", 0))
        return int(sock.getsockname()[1])


def wait_port(port: int, proc: subprocess.Popen[bytes], timeout_s: float) -> None:
    deadline = time.monotonic() + timeout_s
    while True:
        if proc.poll() is not None:
            raise RuntimeError(f"the device server exited with {proc.returncode} before listening")
        try:
            with socket.create_connection(("127.0.0.1", port), timeout=0.5):
                return
        except OSError:
            if time.monotonic() > deadline:
                raise RuntimeError(
                    f"the device server did not listen on 127.0.0.1:{port} within {timeout_s:g} s"
                ) from None
            time.sleep(0.1)


def stop_process(proc: subprocess.Popen[Any] | None, name: str, grace_s: float = 5.0) -> None:
    """SIGTERM, then SIGKILL after grace_s; never raises."""
    if proc is None or proc.poll() is not None:
        return
    try:
        proc.send_signal(signal.SIGTERM)
        proc.wait(timeout=grace_s)
    except subprocess.TimeoutExpired:
        print(f"run_guest: {name} ignored SIGTERM; killing it", file=sys.stderr)
        proc.kill()
        proc.wait(timeout=grace_s)
    except OSError:
        pass


def server_command(mode: str, python: str, port: int, device: str) -> list[str] | None:
    """The device server for `mode`, on 127.0.0.1:port (None: the mode needs none)."""
    if mode in ("hcard", "conformance"):
        return [
            python, "-m", "hcard_device.usb.server",
            "--host", "127.0.0.1", "--port", str(port), "--device", device,
        ]  # fmt: skip
    if mode == "echo":
        return [python, str(HERE / "echo_device.py"), "--host", "127.0.0.1", "--port", str(port)]
    if mode == "probe":
        return None
    raise ValueError(f"unknown mode {mode!r}")


def kernel_arg(name: str, *values: str) -> str:
    """`hcard.NAME=V1,V2,...` for the guest's /init (which turns the commas into spaces)."""
    for value in values:
        if not value or any(c.isspace() or c in ",\"'" for c in value):
            raise ValueError(
                f"{name}: {value!r} cannot go on the kernel command line (empty, or has a space, "
                f"quote or comma); move the repository/interpreter to a plain path"
            )
    return f"hcard.{name}={','.join(values)}"


def guest_visible(path: Path) -> None:
    for hidden in HIDDEN_IN_GUEST:
        if path == Path(hidden) or Path(hidden) in path.parents:
            raise ValueError(f"{path} is under {hidden}, which the guest cannot see from the host")


def qemu_command(
    kernel: Path, initrd: Path, append: str, *, memory_mb: int, smp: int, accel: str
) -> list[str]:
    options: list[tuple[str, ...]] = [
        ("-accel", accel),
        # numpy and friends need more than the default qemu64 CPU's SSE2 (x86-64-v2 and up).
        ("-cpu", "max"),
        ("-m", str(memory_mb)),
        ("-smp", str(smp)),
        ("-nodefaults", "-no-user-config", "-no-reboot"),
        ("-display", "none"),
        ("-monitor", "none"),
        ("-serial", "stdio"),
        ("-kernel", str(kernel)),
        ("-initrd", str(initrd)),
        ("-append", append),
        # User-mode networking: nothing leaves this process; the guest's 10.0.2.2 is the host's
        # 127.0.0.1, where the device server listens.
        ("-netdev", "user,id=net0"),
        ("-device", "virtio-net-pci,netdev=net0,romfile="),  # no PXE ROM: -kernel boots
        # The host root, read-only, over 9p (multidevs=remap: it spans several filesystems).
        (
            "-virtfs",
            "local,path=/,mount_tag=hostroot,security_model=none,readonly=on,multidevs=remap",
        ),
    ]
    return [QEMU, *(word for option in options for word in option)]


def pump(stream: IO[bytes], log: IO[str], lines: queue.Queue[str | None], echo: bool) -> None:
    """Copy QEMU's console to the log (and the queue) line by line, until EOF."""
    for raw in iter(stream.readline, b""):
        line = raw.decode("utf-8", "replace").rstrip("\r\n")
        log.write(line + "\n")
        log.flush()
        if echo:
            print(line, file=sys.stderr, flush=True)
        lines.put(line)
    lines.put(None)


def tail(path: Path, n: int = 60) -> str:
    try:
        return "\n".join(path.read_text(errors="replace").splitlines()[-n:])
    except OSError as exc:
        return f"(no log: {exc})"


def run(args: argparse.Namespace) -> dict[str, Any]:
    cache = cache_dir()
    kernel = find_kernel(cache)
    initrd = cache / "initramfs.cpio.gz"
    assert kernel is not None  # checked by missing_parts() in main()
    log_path = Path(args.log) if args.log else cache / f"console-{args.mode}.log"
    log_path.parent.mkdir(parents=True, exist_ok=True)
    server_log_path = log_path.with_name(log_path.stem + "-server.log")
    python = args.python
    guest_visible(REPO)
    guest_visible(Path(python))

    port = args.port or free_port()
    payload_args = [args.mode, "--server", "10.0.2.2", "--port", str(port), "--busid", args.busid]
    if args.mode == "conformance":
        payload_args += ["--timing", args.timing]
        if args.checks:
            payload_args += ["--checks", args.checks]
    for option in ("card", "track"):
        value = getattr(args, option)
        if value:
            path = Path(value).resolve()
            if not path.is_file():
                raise ValueError(f"--{option} {value}: no such file")
            guest_visible(path)
            payload_args += [f"--{option}", str(path)]
    append = " ".join(
        [
            "console=ttyS0",
            "quiet",
            "loglevel=3",
            "panic=-1",
            kernel_arg("python", python),
            kernel_arg("repo", str(REPO)),
            kernel_arg("payload", str(HERE / "payload.py")),
            kernel_arg("args", *payload_args),
        ]
    )
    summary: dict[str, Any] = {"ok": False, "mode": args.mode, "log": str(log_path)}
    server: subprocess.Popen[bytes] | None = None
    qemu: subprocess.Popen[bytes] | None = None
    t_start = time.monotonic()
    with open(log_path, "w") as log, open(server_log_path, "wb") as server_log:
        try:
            cmd = None if args.no_server else server_command(args.mode, python, port, args.device)
            if cmd is not None:
                log.write(f"# server: {' '.join(cmd)}\n")
                server = subprocess.Popen(
                    cmd,
                    cwd=REPO,
                    stdin=subprocess.DEVNULL,
                    stdout=server_log,
                    stderr=subprocess.STDOUT,
                )
                wait_port(port, server, args.server_timeout)
                summary["server_ready_s"] = round(time.monotonic() - t_start, 2)
            qcmd = qemu_command(
                kernel, initrd, append, memory_mb=args.memory, smp=args.smp, accel=args.accel
            )
            log.write(f"# qemu: {' '.join(qcmd)}\n")
            log.flush()
            t_boot = time.monotonic()
            qemu = subprocess.Popen(
                qcmd,
                stdin=subprocess.DEVNULL,
                stdout=subprocess.PIPE,
                stderr=subprocess.STDOUT,
            )
            assert qemu.stdout is not None
            lines: queue.Queue[str | None] = queue.Queue()
            threading.Thread(
                target=pump, args=(qemu.stdout, log, lines, args.verbose), daemon=True
            ).start()
            deadline = t_boot + args.timeout
            result: dict[str, Any] | None = None
            failure: str | None = None
            while result is None and failure is None:
                remaining = deadline - time.monotonic()
                if remaining <= 0:
                    failure = f"timed out after {args.timeout:g} s without a result line"
                    break
                try:
                    line = lines.get(timeout=min(remaining, 1.0))
                except queue.Empty:
                    continue
                if line is None:
                    failure = f"QEMU exited ({qemu.wait()}) without a result line"
                elif line.startswith(INIT_MARKER) and "boot_s" not in summary:
                    summary["boot_s"] = round(time.monotonic() - t_boot, 2)
                elif line.startswith(MARKER):
                    try:
                        result = json.loads(line[len(MARKER) :])
                    except json.JSONDecodeError as exc:
                        failure = f"unparsable result line ({exc}): {line}"
                elif line.startswith(FAIL_MARKER):
                    failure = "guest init failed: " + line[len(FAIL_MARKER) :]
            summary["guest_s"] = round(time.monotonic() - t_boot, 2)
            if result is not None:
                summary["payload"] = result
                summary["ok"] = bool(result.get("ok"))
                if not summary["ok"]:
                    failure = f"payload failed: {result.get('error', 'no error given')}"
                try:  # /init powers off right after the payload
                    qemu.wait(timeout=15)
                except subprocess.TimeoutExpired:
                    log.write("# run_guest: QEMU did not power off within 15 s; killing it\n")
            if failure is not None:
                summary["error"] = failure
        except (OSError, RuntimeError, ValueError) as exc:
            summary["error"] = str(exc)
        finally:
            stop_process(qemu, "QEMU")
            stop_process(server, "device server")
            summary["total_s"] = round(time.monotonic() - t_start, 2)
    if server is not None:
        summary["server_log"] = str(server_log_path)
        if server.returncode not in (0, -signal.SIGTERM, None):
            summary.setdefault("server_exit", server.returncode)
    return summary


def main(argv: Sequence[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description="Boot the hcard QEMU guest tier.")
    parser.add_argument(
        "--mode",
        choices=("hcard", "conformance", "echo", "probe"),
        default="hcard",
        help="hcard: the reference device and the hidapi driver; conformance: the device "
        "level of the conformance suite over hid://; echo: a minimal HID device on the usbip "
        "package (kernel path only); probe: boot + 9p only",
    )
    parser.add_argument(
        "--device", choices=("evita", "coupled"), default="evita", help="hcard mode: the variant"
    )
    parser.add_argument("--card", help="hcard mode: card file to upload (default: built in)")
    parser.add_argument("--track", help="hcard mode: finger track CSV (default: built in)")
    parser.add_argument(
        "--timing", default="software-emulation",
        help="conformance mode: the timing class whose thresholds apply",
    )
    parser.add_argument(
        "--checks", default="", help="conformance mode: comma-separated checks (default: all)"
    )
    parser.add_argument("--timeout", type=float, default=240.0, help="guest time limit, s")
    parser.add_argument("--server-timeout", type=float, default=30.0)
    parser.add_argument("--port", type=int, default=0, help="server port (0: a free one)")
    parser.add_argument("--busid", default="1-1")
    parser.add_argument(
        "--no-server",
        action="store_true",
        help="do not start a device server: use the one already listening on 127.0.0.1:--port",
    )
    parser.add_argument(
        "--python", default=sys.executable, help="host interpreter the guest runs the payload with"
    )
    parser.add_argument("--log", help="console log file (default build/guest/console-MODE.log)")
    parser.add_argument("--memory", type=int, default=512, help="guest memory, MiB")
    parser.add_argument("--smp", type=int, default=1)
    parser.add_argument("--accel", default="tcg", help="QEMU accelerator (default tcg)")
    parser.add_argument("-v", "--verbose", action="store_true", help="echo the console to stderr")
    args = parser.parse_args(argv)

    if args.no_server and not args.port:
        parser.error("--no-server needs --port")
    missing = missing_parts()
    if missing:
        print(
            f"run_guest: the guest tier is not installed: missing {', '.join(missing)}; "
            f"{INSTALL_HINT}",
            file=sys.stderr,
        )
        return EXIT_NOT_INSTALLED
    # SIGTERM unwinds like Ctrl-C, so run()'s cleanup stops QEMU and the server.  (They stay in
    # this process group: whoever must kill this runner outright can kill the group.)
    signal.signal(signal.SIGTERM, lambda signum, _frame: sys.exit(128 + signum))
    try:
        summary = run(args)
    except ValueError as exc:  # a bad argument or a path the guest cannot see
        print(f"run_guest: {exc}", file=sys.stderr)
        return 2
    print(json.dumps(summary, sort_keys=True), flush=True)
    if not summary["ok"]:
        if "server_log" in summary:
            print(
                f"--- device server log tail ({summary['server_log']}) ---\n"
                f"{tail(Path(summary['server_log']), 30)}",
                file=sys.stderr,
            )
        print(
            f"run_guest: FAILED: {summary.get('error')}\n--- console log tail "
            f"({summary['log']}) ---\n{tail(Path(summary['log']))}",
            file=sys.stderr,
        )
        return 1
    return 0


if __name__ == "__main__":
    sys.exit(main())
