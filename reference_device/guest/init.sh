#!/bin/busybox sh
# shellcheck shell=dash
# /init of the hcard guest-tier initramfs (busybox sh, PID 1 inside the QEMU guest).
#
# Mounts proc/sys/dev, loads the kernel modules listed in /etc/modules.load (dependency order,
# resolved by build_initramfs.sh), brings up QEMU user-mode networking (guest 10.0.2.15, the
# host's loopback reachable as 10.0.2.2), mounts the host root filesystem read-only over 9p at
# /host, and runs the payload with the host's own Python inside a chroot of /host.  Every line
# the runner parses starts with "hcard-guest:".  It always ends with `poweroff -f`.
#
# Kernel command-line parameters (set by run_guest.py):
#   hcard.python=PATH   host Python interpreter           hcard.repo=PATH  host checkout
#   hcard.payload=PATH  payload script (run with python)  hcard.args=A,B   payload args (',' = ' ')
set -u
/bin/busybox --install -s /bin
export PATH=/bin

say() { echo "hcard-guest: $*"; }
fail() {
    say "FAIL $*"
    poweroff -f
    sleep 5
}
uptime_s() { cut -d' ' -f1 /proc/uptime; }

mkdir -p /proc /sys /dev /host /tmp
mount -t proc proc /proc
mount -t sysfs sysfs /sys
mount -t devtmpfs devtmpfs /dev 2>/dev/null || true
say "init at $(uptime_s) s, kernel $(uname -r)"

while read -r mod; do
    [ -n "$mod" ] || continue
    insmod "/lib/modules/$mod" || fail "insmod $mod"
done </etc/modules.load
say "modules loaded at $(uptime_s) s"

# Parameters from the kernel command line.
python="" repo="" payload="" args=""
read -r cmdline </proc/cmdline
for word in $cmdline; do
    case "$word" in
        hcard.python=*) python="${word#hcard.python=}" ;;
        hcard.repo=*) repo="${word#hcard.repo=}" ;;
        hcard.payload=*) payload="${word#hcard.payload=}" ;;
        hcard.args=*) args="$(echo "${word#hcard.args=}" | tr ',' ' ')" ;;
    esac
done
if [ -z "$python" ] || [ -z "$repo" ] || [ -z "$payload" ]; then
    fail "kernel command line lacks hcard.python/hcard.repo/hcard.payload"
fi

# Network: QEMU user mode (slirp).  No DHCP needed: its addresses are fixed.
ip link set lo up
ip link set eth0 up || fail "no eth0 (virtio-net not found)"
ip addr add 10.0.2.15/24 dev eth0
ip route add default via 10.0.2.2
say "network up at $(uptime_s) s"

# The host root, read-only.
mount -t 9p -o trans=virtio,version=9p2000.L,ro,cache=loose,msize=262144 hostroot /host \
    || fail "mount 9p hostroot (is -virtfs ... mount_tag=hostroot given?)"
mount -t proc proc /host/proc || fail "mount /host/proc"
mount -t sysfs sysfs /host/sys || fail "mount /host/sys"
mount -t devtmpfs devtmpfs /host/dev || fail "mount /host/dev"
# Writable scratch: /run (usbip records its ports in /run/vhci_hcd) and TMPDIR=/run/tmp.  The
# host's /tmp stays visible (read-only): the runner may put input files there.
mount -t tmpfs tmpfs /host/run || fail "mount /host/run"
mkdir -p /host/run/tmp
say "host root mounted at $(uptime_s) s"

# Test inside the chroot: a venv's python3 is an absolute symlink into the host tree.
chroot /host test -x "$python" || fail "host python $python not found in the 9p share"
# shellcheck disable=SC2086,SC2016  # args is a list of words; $1/$@ belong to the inner sh
chroot /host /usr/bin/env -i PATH=/usr/local/sbin:/usr/local/bin:/usr/sbin:/usr/bin:/sbin:/bin \
    HOME=/root LANG=C.UTF-8 TMPDIR=/run/tmp PYTHONDONTWRITEBYTECODE=1 PYTHONUNBUFFERED=1 \
    /bin/sh -c 'cd "$1" && shift && exec "$@"' sh "$repo" "$python" "$payload" $args
rc=$?
say "payload exit $rc at $(uptime_s) s"
sync
poweroff -f
sleep 5
