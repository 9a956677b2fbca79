#!/usr/bin/env bash
# Build the guest-tier initramfs: busybox-static, the kernel modules the guest needs (with their
# dependencies resolved by `modprobe --show-depends` against the unpacked kernel) and init.sh as
# /init.  Output: <cache>/initramfs.cpio.gz, where <cache> is HCARD_GUEST_DIR or <repo>/build/guest.
# Needs the kernel unpacked by install.sh (<cache>/kernel/current).
set -euo pipefail

here="$(cd "$(dirname "${BASH_SOURCE[0]}")" && pwd)"
repo="$(cd "$here/../.." && pwd)"
cache="${HCARD_GUEST_DIR:-$repo/build/guest}"
kroot="$cache/kernel/current"
out="$cache/initramfs.cpio.gz"

# What the guest loads: virtio PCI transport + network (QEMU user networking), 9p for the host
# root, vhci-hcd (the USB/IP client host controller), and the HID stack (hid.ko carries hidraw).
modules=(virtio_pci virtio_net 9pnet_virtio 9p vhci-hcd usbhid hid-generic)

log() { printf 'guest-initramfs: %s\n' "$*"; }
die() { printf 'guest-initramfs: ERROR: %s\n' "$*" >&2; exit 1; }

[[ -d "$kroot/lib/modules" ]] \
    || die "no unpacked kernel in $kroot: run reference_device/guest/install.sh"
kver="$(basename "$(readlink -f "$kroot")")"
[[ -f "$kroot/lib/modules/$kver/modules.dep" ]] \
    || die "$kroot/lib/modules/$kver/modules.dep missing: run reference_device/guest/install.sh"
busybox="$(command -v busybox || true)"
[[ -n "$busybox" ]] || die "busybox not found: apt-get install busybox-static"
if ldd "$busybox" >/dev/null 2>&1; then
    die "$busybox is dynamically linked: install busybox-static (not busybox)"
fi
command -v cpio >/dev/null 2>&1 || die "cpio not found: apt-get install cpio"
command -v modprobe >/dev/null 2>&1 || die "modprobe not found: apt-get install kmod"

stage="$(mktemp -d "$cache/initramfs.XXXXXX")"
trap 'rm -rf "$stage"' EXIT
mkdir -p "$stage"/{bin,dev,etc,proc,sys,host,tmp,"lib/modules/$kver"}
cp "$busybox" "$stage/bin/busybox"
install -m 0755 "$here/init.sh" "$stage/init"

: >"$stage/etc/modules.load"
declare -A seen=()
for mod in "${modules[@]}"; do
    deps="$(modprobe --show-depends -d "$kroot" -S "$kver" "$mod")" \
        || die "modprobe --show-depends $mod failed against $kroot"
    while read -r verb path _; do
        [[ "$verb" == "insmod" ]] || continue   # 'builtin X' lines need nothing
        rel="${path#"$kroot"}"          # modprobe prints <kroot>/./lib/modules/<kver>/...
        rel="${rel#/}"
        rel="${rel#./}"
        rel="${rel#lib/modules/}"
        [[ -n "${seen[$rel]:-}" ]] && continue
        seen[$rel]=1
        src="$kroot/lib/modules/$rel"
        [[ -f "$src" ]] || src="$path"
        dst_rel="$rel"
        case "$rel" in
            *.ko.xz) dst_rel="${rel%.xz}" ;;
            *.ko.zst) dst_rel="${rel%.zst}" ;;
            *.ko.gz) dst_rel="${rel%.gz}" ;;
        esac
        mkdir -p "$(dirname "$stage/lib/modules/$dst_rel")"
        case "$rel" in
            *.ko.xz) xz -dc "$src" >"$stage/lib/modules/$dst_rel" ;;
            *.ko.zst) zstd -qdc "$src" >"$stage/lib/modules/$dst_rel" ;;
            *.ko.gz) gzip -dc "$src" >"$stage/lib/modules/$dst_rel" ;;
            *) cp "$src" "$stage/lib/modules/$dst_rel" ;;
        esac
        echo "$dst_rel" >>"$stage/etc/modules.load"
    done <<<"$deps"
done
log "kernel $kver, $(wc -l <"$stage/etc/modules.load") modules:"
sed 's/^/    /' "$stage/etc/modules.load"

(cd "$stage" && find . -print0 | LC_ALL=C sort -z | cpio --null -o -H newc --quiet -R 0:0) \
    | gzip -1 >"$out.tmp"
mv "$out.tmp" "$out"
log "wrote $out ($(du -h "$out" | cut -f1))"
