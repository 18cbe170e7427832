#!/usr/bin/env bash
# Builds the stand-in guest image: Debian's signed kernel and an initramfs that runs the
# Linux arena-guest (stub backend) at boot, for testing the QEMU machinery (overlays,
# QMP, snapshots, the installer path) without a Windows image. See docs/vm-standin.md.
#
# Usage: scripts/build-standin-image.sh [OUT_DIR]      (default: target/standin)
#
# Writes into OUT_DIR:
#   golden.qcow2    disk that boots on BIOS (SYSLINUX) and on UEFI with Secure Boot
#                   (Debian's signed shim, GRUB and kernel): a FAT volume with the kernel
#                   and initrd
#   installer.iso   CD (El Torito for BIOS with ISOLINUX and for UEFI with shim and GRUB)
#                   booting the same kernel and initrd with arena.mode=install;
#                   it writes the disk image onto the first disk and copies the OEM
#                   folder's token onto it
#   standin.json    manifest: kernel, guest binary sha256, guest port, screen size, files
#   cache/          the downloaded packages (kept: a rerun reuses them)
#
# Environment (all optional):
#   ARENA_GUEST_BIN          the Linux arena-guest to embed (default target/debug/arena-guest)
#   ARENA_STANDIN_KERNEL     kernel package (default: what linux-image-amd64 depends on)
#   SOURCE_DATE_EPOCH        the time stamped on every file in the images (default: a fixed
#                            one), so the same inputs give byte-identical outputs
#
# Needs these Debian packages: apt dpkg binutils libc-bin busybox-static syslinux
# syslinux-common isolinux mtools dosfstools xorriso cpio gzip qemu-utils coreutils.
# No root: the packages (kernel, shim-signed, grub-efi-amd64-signed) are fetched with
# apt-get download and unpacked with dpkg-deb -x, the disks are written with mtools.
set -euo pipefail
# mkfs.vfat lives in /usr/sbin, which a non-root user's PATH often lacks.
export PATH=$PATH:/usr/sbin:/sbin

cd "$(dirname "$0")/.."
ROOT=$PWD
OUT=${1:-target/standin}
GUEST_BIN=${ARENA_GUEST_BIN:-target/debug/arena-guest}
STANDIN=$ROOT/scripts/standin
# What QEMU's screendump of the VGA text screen (80x25, 9x16 glyphs) gives.
SCREEN=720x400
GUEST_PORT=5000
# mtools (so syslinux and mcopy), xorriso and this script read it; 2024-01-01 by default.
export SOURCE_DATE_EPOCH=${SOURCE_DATE_EPOCH:-1704067200}
# Drivers the image loads at boot (their dependencies are added): virtio disks and
# network, FAT with the code pages its mount needs, the ACPI power button and evdev to
# read it.
# The CD-ROM (IDE on `pc`, AHCI on q35) and ISO 9660 (with Joliet) read the OEM media of
# `arena vm prepare`. (The TPM's tpm_tis is built into the generic kernel.) efivarfs reads
# the firmware's SecureBoot variable. bochs drives QEMU's standard VGA in the mode its
# EDID prefers (`-device VGA,xres=,yres=`), on BIOS as on UEFI.
MODULES=(virtio_pci virtio_blk virtio_scsi sd_mod virtio_net vfat nls_cp437 nls_ascii
    nls_utf8 nls_iso8859-1 button evdev ata_piix ahci sr_mod isofs efivarfs bochs)

die() {
    echo "build-standin-image: $*" >&2
    exit 1
}

say() {
    echo "build-standin-image: $*"
}

# Every tool the build runs, with the Debian package that has it.
missing=()
need() {
    command -v "$1" >/dev/null 2>&1 || missing+=("$1 (package $2)")
}
need apt-get apt
need apt-cache apt
need dpkg-deb dpkg
need objcopy binutils
need strip binutils
need readelf binutils
need ldd libc-bin
need busybox busybox-static
need syslinux syslinux
need mcopy mtools
need mmd mtools
need mkfs.vfat dosfstools
need xorriso xorriso
need cpio cpio
need gzip gzip
need qemu-img qemu-utils
need sha256sum coreutils
[ ${#missing[@]} -eq 0 ] || die "missing: ${missing[*]}"
ISOLINUX_BIN=/usr/lib/ISOLINUX/isolinux.bin
ISOHDPFX=/usr/lib/ISOLINUX/isohdpfx.bin
LDLINUX_C32=/usr/lib/syslinux/modules/bios/ldlinux.c32
[ -f "$ISOLINUX_BIN" ] || die "missing $ISOLINUX_BIN (package isolinux)"
[ -f "$ISOHDPFX" ] || die "missing $ISOHDPFX (package isolinux)"
[ -f "$LDLINUX_C32" ] || die "missing $LDLINUX_C32 (package syslinux-common)"
BUSYBOX=$(command -v busybox)
if readelf -d "$BUSYBOX" 2>/dev/null | grep -q NEEDED; then
    die "$BUSYBOX is dynamically linked: install busybox-static (it replaces busybox)"
fi
[ -f "$GUEST_BIN" ] || die "no guest binary at $GUEST_BIN: run cargo build -p arena-guest, or set ARENA_GUEST_BIN"

mkdir -p "$OUT/cache"
OUT=$(cd "$OUT" && pwd)
CACHE=$OUT/cache
WORK=$OUT/work
rm -rf "$WORK"
mkdir -p "$WORK"

# --- packages -------------------------------------------------------------------------
# The newest cached .deb of package $1 in $CACHE, downloaded first if none is.
debian_package() {
    local deb
    deb=$(find "$CACHE" -maxdepth 1 -name "${1}_*.deb" | sort | tail -n1)
    if [ -z "$deb" ]; then
        say "downloading $1" >&2
        (cd "$CACHE" && apt-get download "$1" >&2) || die "apt-get download $1 failed"
        deb=$(find "$CACHE" -maxdepth 1 -name "${1}_*.deb" | sort | tail -n1)
        [ -n "$deb" ] || die "apt-get download $1 left no .deb in $CACHE"
    else
        say "reusing $(basename "$deb")" >&2
    fi
    echo "$deb"
}

# The generic kernel, not the cloud one: it has the AHCI driver (q35's CD-ROMs) and the
# TPM's TIS driver. Debian signs it for Secure Boot (the linux-signed-amd64 source).
KERNEL_PKG=${ARENA_STANDIN_KERNEL:-}
if [ -z "$KERNEL_PKG" ]; then
    KERNEL_PKG=$(apt-cache depends linux-image-amd64 2>/dev/null \
        | sed -n 's/^ *Depends: \(linux-image-[0-9].*\)$/\1/p' | head -n1) || true
fi
if [ -z "$KERNEL_PKG" ]; then
    # No package lists (apt-get update not run, or offline): fall back to the cache.
    cached=$(find "$CACHE" -maxdepth 1 -name 'linux-image-[0-9]*[0-9]-amd64_*.deb' | sort | tail -n1)
    [ -n "$cached" ] || die "cannot tell the kernel's version (apt-cache depends linux-image-amd64 gave nothing; run apt-get update) and none is cached in $CACHE"
    KERNEL_PKG=$(basename "$cached" | cut -d_ -f1)
fi
deb=$(debian_package "$KERNEL_PKG")
dpkg-deb -x "$deb" "$WORK/kernel"
KVER=${KERNEL_PKG#linux-image-}
VMLINUZ=$WORK/kernel/boot/vmlinuz-$KVER
MODDIR=$WORK/kernel/lib/modules/$KVER
if [ ! -f "$VMLINUZ" ] || [ ! -d "$MODDIR" ]; then
    die "$deb holds no boot/vmlinuz-$KVER and lib/modules/$KVER"
fi

# Secure Boot's chain, as Debian boots it: OVMF checks shim against Microsoft's third-party
# UEFI CA (in the db of OVMF_VARS_4M.ms.fd), shim checks GRUB and the kernel against
# Debian's key built into it. shim, started as \EFI\BOOT\BOOTX64.EFI, starts
# grubx64.efi from its own folder; that GRUB reads grub.cfg beside it ($cmdpath).
SHIM=$WORK/shim/usr/lib/shim/shimx64.efi.signed
GRUB_EFI=$WORK/grub/usr/lib/grub/x86_64-efi-signed/grubx64.efi.signed
SHIM_DEB=$(debian_package shim-signed)
GRUB_DEB=$(debian_package grub-efi-amd64-signed)
dpkg-deb -x "$SHIM_DEB" "$WORK/shim"
dpkg-deb -x "$GRUB_DEB" "$WORK/grub"
[ -f "$SHIM" ] || die "shim-signed holds no ${SHIM#"$WORK/shim"}"
[ -f "$GRUB_EFI" ] || die "grub-efi-amd64-signed holds no ${GRUB_EFI#"$WORK/grub"}"
# The EFI folder of a boot volume: shim, GRUB and the GRUB configuration $2, into FAT image $1.
efi_boot_files() {
    local dir=$WORK/efi-files
    rm -rf "$dir"
    mkdir -p "$dir"
    cp "$SHIM" "$dir/BOOTX64.EFI"
    cp "$GRUB_EFI" "$dir/grubx64.efi"
    cp "$2" "$dir/grub.cfg"
    touch -d "@$SOURCE_DATE_EPOCH" "$dir"/*
    mmd -i "$1" ::/EFI ::/EFI/BOOT
    mcopy -m -i "$1" "$dir/BOOTX64.EFI" "$dir/grubx64.efi" "$dir/grub.cfg" ::/EFI/BOOT/
}

# --- initramfs ------------------------------------------------------------------------
RD=$WORK/initramfs
mkdir -p "$RD"/{bin,sbin,etc,lib/modules,lib64,usr/bin,root,install}

cp "$BUSYBOX" "$RD/bin/busybox"
install -m 0755 "$STANDIN/init" "$RD/init"
install -m 0755 "$STANDIN/udhcpc.script" "$RD/etc/udhcpc.script"
printf 'GUEST_PORT=%s\nSCREEN=%s\n' "$GUEST_PORT" "$SCREEN" >"$RD/etc/arena-standin.env"
printf 'root:x:0:0:root:/root:/bin/sh\n' >"$RD/etc/passwd"
printf 'root:x:0:\n' >"$RD/etc/group"
printf '127.0.0.1 localhost\n' >"$RD/etc/hosts"

# The guest, stripped, with the shared libraries and the loader it names.
strip -o "$RD/usr/bin/arena-guest" "$GUEST_BIN"
GUEST_SHA=$(sha256sum "$GUEST_BIN" | cut -d' ' -f1)
libs=$(ldd "$GUEST_BIN" | awk '$2 == "=>" && $3 ~ /^\// { print $3 } $1 ~ /^\// { print $1 }')
[ -n "$libs" ] || die "ldd lists no libraries for $GUEST_BIN"
for lib in $libs; do
    mkdir -p "$RD$(dirname "$lib")"
    cp -L "$lib" "$RD$lib"
done
# The loader must also be where the binary's interpreter field says.
interp=$(readelf -l "$GUEST_BIN" | sed -n 's/.*Requesting program interpreter: \(.*\)]/\1/p')
if [ -n "$interp" ] && [ ! -e "$RD$interp" ]; then
    mkdir -p "$RD$(dirname "$interp")"
    cp -L "$interp" "$RD$interp"
fi

# Modules, dependencies first, listed in load order for init's insmod loop.
module_path() {
    local found
    found=$(find "$MODDIR/kernel" -name "$1.ko" -o -name "$1.ko.xz" -o -name "$1.ko.zst" | head -n1)
    [ -n "$found" ] || found=$(find "$MODDIR/kernel" -name "${1//_/-}.ko" | head -n1)
    [ -n "$found" ] || die "kernel $KVER has no module $1"
    case "$found" in *.ko) ;; *) die "$found is compressed; this script expects plain .ko files" ;; esac
    echo "$found"
}
module_deps() {
    objcopy -O binary --only-section=.modinfo "$1" /dev/stdout | tr '\0' '\n' \
        | sed -n 's/^depends=//p' | tr ',' ' '
}
declare -A loaded=()
order=()
add_module() {
    local name=$1 path dep
    [ -z "${loaded[$name]:-}" ] || return 0
    loaded[$name]=1
    path=$(module_path "$name")
    for dep in $(module_deps "$path"); do
        add_module "$dep"
    done
    cp "$path" "$RD/lib/modules/"
    order+=("$(basename "$path")")
}
for module in "${MODULES[@]}"; do
    add_module "$module"
done
printf '%s\n' "${order[@]}" >"$RD/lib/modules/load-order"
say "kernel $KVER, ${#order[@]} modules: ${order[*]}"

# newc archives, sorted, owned by root, every time stamp SOURCE_DATE_EPOCH. gzip: every
# kernel reads it, and under TCG it unpacks as fast as zstd (xz takes 3 s longer).
make_cpio() {
    find "$1" -exec touch -h -d "@$SOURCE_DATE_EPOCH" {} +
    (cd "$1" && find . -mindepth 1 | LC_ALL=C sort | cpio -o -H newc -R 0:0 --reproducible --quiet)
}
make_cpio "$RD" | gzip -9 -n >"$WORK/initrd.img"

# --- golden disk ----------------------------------------------------------------------
# A FAT "superfloppy" (no partition table) with SYSLINUX in its boot sector: room for the
# kernel, the initrd and 1.5 GiB spare, for C:\OEM (the installer copies the OEM folder
# there; a test stages 1 GiB). The spare is zeros: sparse in the qcow2 and in the gzip'd
# copy the installer writes (and QEMU turns written zeros into unallocated clusters).
kb() { echo $(( ($(stat -c %s "$1") + 1023) / 1024 )); }
size_kb=$(( ($(kb "$VMLINUZ") + $(kb "$WORK/initrd.img") + $(kb "$SHIM") + $(kb "$GRUB_EFI") \
    + 1536 * 1024 + 1023) / 1024 * 1024 ))
DISK=$WORK/disk.img
mkfs.vfat -C --invariant -i 41524e41 -n ARENA "$DISK" "$size_kb" >/dev/null
touch -d "@$SOURCE_DATE_EPOCH" "$VMLINUZ" "$WORK/initrd.img"
syslinux --install "$DISK"
cp "$STANDIN/syslinux.cfg" "$WORK/syslinux.cfg"
touch -d "@$SOURCE_DATE_EPOCH" "$WORK/syslinux.cfg"
mcopy -m -i "$DISK" "$VMLINUZ" ::/vmlinuz
mcopy -m -i "$DISK" "$WORK/initrd.img" ::/initrd.img
mcopy -m -i "$DISK" "$WORK/syslinux.cfg" ::/syslinux.cfg
efi_boot_files "$DISK" "$STANDIN/grub-disk.cfg"
rm -f "$OUT/golden.qcow2"
qemu-img convert -f raw -O qcow2 "$DISK" "$OUT/golden.qcow2"
# A golden image is read-only: every VM's overlay depends on it unchanged.
chmod a-w "$OUT/golden.qcow2"

# --- installer CD ---------------------------------------------------------------------
# install.img: a second initramfs archive holding the disk image, which the installer
# writes onto the target disk.
mkdir -p "$WORK/install-rd/install"
gzip -9 -n -c "$DISK" >"$WORK/install-rd/install/disk.img.gz"
# How many MiB from the start hold anything but zeros: the installer writes only those
# onto its (blank) target, not the free space's zeros (minutes under emulation).
used_mib=$(( $(stat -c %s "$DISK") / 1048576 ))
while [ "$used_mib" -gt 1 ] \
    && [ -z "$(dd if="$DISK" bs=1M skip=$((used_mib - 1)) count=1 2>/dev/null | tr -d '\0' | head -c1)" ]; do
    used_mib=$((used_mib - 1))
done
echo "$used_mib" >"$WORK/install-rd/install/disk.mib"
make_cpio "$WORK/install-rd" >"$WORK/install.img"
ISO=$WORK/iso
mkdir -p "$ISO/isolinux"
cp "$ISOLINUX_BIN" "$LDLINUX_C32" "$STANDIN/isolinux.cfg" "$ISO/isolinux/"
cp "$VMLINUZ" "$ISO/vmlinuz"
cp "$WORK/initrd.img" "$WORK/install.img" "$ISO/"
# The UEFI El Torito image: a small FAT volume with the EFI folder; its GRUB reads its
# configuration, the kernel and the initrds from the CD's ISO 9660 file system.
mkdir -p "$ISO/boot"
mkfs.vfat -C --invariant -i 41524e42 -n ARENA_EFI "$ISO/boot/efi.img" \
    $(( ($(kb "$SHIM") + $(kb "$GRUB_EFI") + 256 + 63) / 64 * 64 )) >/dev/null
efi_boot_files "$ISO/boot/efi.img" "$STANDIN/grub-install.cfg"
# Started from the El Torito image, GRUB's $cmdpath is the CD's ISO 9660 volume: it reads
# grub.cfg from there.
mkdir -p "$ISO/EFI/BOOT"
cp "$STANDIN/grub-install.cfg" "$ISO/EFI/BOOT/grub.cfg"
find "$ISO" -exec touch -h -d "@$SOURCE_DATE_EPOCH" {} +
rm -f "$OUT/installer.iso"
xorriso -as mkisofs -quiet -o "$OUT/installer.iso" -V ARENA_INSTALL \
    -isohybrid-mbr "$ISOHDPFX" -b isolinux/isolinux.bin -c isolinux/boot.cat \
    -no-emul-boot -boot-load-size 4 -boot-info-table \
    -eltorito-alt-boot -e boot/efi.img -no-emul-boot "$ISO" 2>"$WORK/xorriso.log" \
    || { cat "$WORK/xorriso.log" >&2; die "xorriso could not write installer.iso"; }

# --- manifest -------------------------------------------------------------------------
file_entry() {
    printf '    {"name": "%s", "bytes": %s, "sha256": "%s"}' \
        "$1" "$(stat -c %s "$OUT/$1")" "$(sha256sum "$OUT/$1" | cut -d' ' -f1)"
}
{
    printf '{\n'
    printf '  "kernel_package": "%s",\n' "$KERNEL_PKG"
    printf '  "kernel_version": "%s",\n' "$KVER"
    printf '  "kernel_deb": "%s",\n' "$(basename "$deb")"
    printf '  "uefi_debs": ["%s", "%s"],\n' "$(basename "$SHIM_DEB")" "$(basename "$GRUB_DEB")"
    printf '  "guest_sha256": "%s",\n' "$GUEST_SHA"
    printf '  "guest_port": %s,\n' "$GUEST_PORT"
    printf '  "screen": {"width": %s, "height": %s},\n' "${SCREEN%x*}" "${SCREEN#*x}"
    printf '  "install_kernel_arg": "arena.mode=install",\n'
    printf '  "token_file": "token",\n'
    printf '  "files": [\n%s,\n%s\n  ]\n' "$(file_entry golden.qcow2)" "$(file_entry installer.iso)"
    printf '}\n'
} >"$OUT/standin.json"

say "initrd $(kb "$WORK/initrd.img") KiB, disk $size_kb KiB; wrote golden.qcow2, installer.iso and standin.json in $OUT"
rm -rf "$WORK"
