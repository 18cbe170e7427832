#!/usr/bin/env bash
# Proves the stand-in image works under QEMU software emulation (TCG) and prints the
# figures: boot to health, savevm/loadvm and health after loadvm, a screendump's size,
# clean power-off on system_powerdown, the installer end to end with an OEM token, and a
# boot from virtio-scsi. Every QEMU run has a timeout and is killed on the way out.
#
# Usage: scripts/standin/check.sh [IMAGE_DIR]   (default: ARENA_STANDIN_DIR or target/standin)
#
# Needs qemu-system-x86 and qemu-utils (and python3 for QMP, curl for HTTP).
set -euo pipefail

cd "$(dirname "$0")/../.."
ROOT=$PWD
IMAGES=${1:-${ARENA_STANDIN_DIR:-target/standin}}
IMAGES=$(cd "$IMAGES" && pwd)
QMP=$ROOT/scripts/standin/qmp.py
for tool in qemu-system-x86_64 qemu-img python3 curl; do
    command -v "$tool" >/dev/null || { echo "check: missing $tool" >&2; exit 1; }
done
for file in golden.qcow2 installer.iso standin.json; do
    [ -f "$IMAGES/$file" ] || { echo "check: no $IMAGES/$file: run scripts/build-standin-image.sh" >&2; exit 1; }
done

RUN=$(mktemp -d)
QEMU_PID=
cleanup() {
    if [ -n "$QEMU_PID" ] && kill -0 "$QEMU_PID" 2>/dev/null; then
        kill "$QEMU_PID" 2>/dev/null || true
        wait "$QEMU_PID" 2>/dev/null || true
    fi
    rm -rf "$RUN"
}
trap cleanup EXIT

PORT=$(python3 -c 'import socket; s = socket.socket(); s.bind(("127.0.0.1", 0)); print(s.getsockname()[1])')
GUEST=http://127.0.0.1:$PORT
now() { date +%s.%N; }
since() { python3 -c "import sys; print(f'{float(sys.argv[2]) - float(sys.argv[1]):.1f}')" "$1" "$(now)"; }
fail() {
    echo "check: FAILED: $*" >&2
    echo "--- serial console ---" >&2
    tail -n 40 "$RUN/serial.log" >&2 2>/dev/null || true
    exit 1
}

# start_qemu TIMEOUT_S EXTRA_ARGS...: one VM, user network forwarding $PORT to the guest.
start_qemu() {
    local limit=$1
    shift
    rm -f "$RUN/serial.log" "$RUN/qmp.sock"
    timeout "$limit" qemu-system-x86_64 -accel tcg -machine pc -m 512 -display none \
        -serial "file:$RUN/serial.log" -qmp "unix:$RUN/qmp.sock,server,nowait" \
        -netdev "user,id=n0,hostfwd=tcp:127.0.0.1:$PORT-:5000" -device virtio-net-pci,netdev=n0 \
        "$@" &
    QEMU_PID=$!
}

qmp() { python3 "$QMP" "$RUN/qmp.sock" "$@"; }

# wait_health SECONDS [CURL_ARGS...]: until /v1/health answers 200.
wait_health() {
    local deadline=$(($(date +%s) + $1))
    shift
    while [ "$(date +%s)" -lt "$deadline" ]; do
        kill -0 "$QEMU_PID" 2>/dev/null || fail "QEMU exited before the guest answered"
        if curl -sf -m 2 -o /dev/null "$GUEST/v1/health"; then
            return 0
        fi
        sleep 0.2
    done
    fail "no health answer within the time allowed"
}

# wait_exit SECONDS: until QEMU exits by itself.
wait_exit() {
    local deadline=$(($(date +%s) + $1))
    while kill -0 "$QEMU_PID" 2>/dev/null; do
        [ "$(date +%s)" -lt "$deadline" ] || fail "QEMU still running after system_powerdown"
        sleep 0.1
    done
    wait "$QEMU_PID" || fail "QEMU exited with an error"
    QEMU_PID=
}

status() { curl -s -m 5 -o /dev/null -w '%{http_code}' "$@"; }

echo "== normal boot from an overlay on golden.qcow2 (virtio-blk)"
qemu-img create -q -f qcow2 -F qcow2 -b "$IMAGES/golden.qcow2" "$RUN/overlay.qcow2"
started=$(now)
start_qemu 300 -drive "file=$RUN/overlay.qcow2,format=qcow2,if=virtio"
wait_health 240
echo "boot to health: $(since "$started") s"

qmp screendump "{\"filename\": \"$RUN/screen.ppm\"}" >/dev/null
python3 - "$RUN/screen.ppm" <<'EOF' || fail "screendump"
import re, sys
data = open(sys.argv[1], "rb").read()
header = re.match(rb"P6\s+(\d+)\s+(\d+)\s+255\s", data)
pixels = data[header.end():]
lit = sum(1 for i in range(0, len(pixels), 3) if pixels[i:i + 3] != b"\0\0\0")
print(f"screendump: {header.group(1).decode()}x{header.group(2).decode()}, {lit} non-black pixels")
sys.exit(0 if lit else 1)
EOF

file_url() { echo "$GUEST/v1/files?path=C:/Users/Docker/Desktop/$1"; }
[ "$(status -X PUT --data-binary kept "$(file_url kept.txt)")" = 200 ] || fail "PUT kept.txt"
started=$(now)
qmp hmp "savevm ready" || fail "savevm"
echo "savevm: $(since "$started") s"
[ "$(status -X PUT --data-binary gone "$(file_url gone.txt)")" = 200 ] || fail "PUT gone.txt"
[ "$(status "$(file_url gone.txt)")" = 200 ] || fail "gone.txt was not written"
started=$(now)
qmp hmp "loadvm ready" || fail "loadvm"
echo "loadvm: $(since "$started") s"
wait_health 60
echo "health after loadvm: $(since "$started") s (from the loadvm command)"
[ "$(status "$(file_url kept.txt)")" = 200 ] || fail "kept.txt is gone after loadvm"
[ "$(status "$(file_url gone.txt)")" = 404 ] || fail "gone.txt survived loadvm"
echo "after loadvm: the file written before savevm is there, the one written after is gone"

started=$(now)
qmp system_powerdown >/dev/null
wait_exit 30
echo "system_powerdown to QEMU exit: $(since "$started") s"

echo "== normal boot from virtio-scsi"
qemu-img create -q -f qcow2 -F qcow2 -b "$IMAGES/golden.qcow2" "$RUN/overlay-scsi.qcow2"
started=$(now)
start_qemu 300 -device virtio-scsi-pci,id=scsi0 \
    -drive "file=$RUN/overlay-scsi.qcow2,format=qcow2,if=none,id=d0" -device scsi-hd,drive=d0
wait_health 240
grep -aq "no token on /dev/sda" "$RUN/serial.log" || fail "the disk was not found as /dev/sda"
echo "boot to health (virtio-scsi): $(since "$started") s"
qmp system_powerdown >/dev/null
wait_exit 30

echo "== installer: blank 64G disk, installer.iso, OEM media (answer file + token), -boot order=cd"
# The stand-in Setup wants an answer file on removable media, 4 GB and 2 processors,
# a 64 GB disk, and (without a TPM) the LabConfig bypass keys: a minimal answer file.
mkdir -p "$RUN/media/OEM"
TOKEN=$(python3 -c 'import secrets; print(secrets.token_hex(32))')
echo "$TOKEN" >"$RUN/media/OEM/arena-token"
printf '@echo off\r\n' >"$RUN/media/OEM/install.bat"
echo marker >"$RUN/media/ARENA-OEM.TXT"
cat >"$RUN/media/autounattend.xml" <<'XML'
<unattend xmlns="urn:schemas-microsoft-com:unattend"><settings pass="windowsPE"><component name="Microsoft-Windows-Setup">
<ImageInstall><OSImage><InstallFrom><MetaData><Key>/IMAGE/INDEX</Key><Value>1</Value></MetaData></InstallFrom></OSImage></ImageInstall>
<UserData><AcceptEula>true</AcceptEula></UserData><RunSynchronous>
<RunSynchronousCommand><Path>reg.exe add "HKLM\SYSTEM\Setup\LabConfig" /v BypassTPMCheck /t REG_DWORD /d 1 /f</Path></RunSynchronousCommand>
<RunSynchronousCommand><Path>reg.exe add "HKLM\SYSTEM\Setup\LabConfig" /v BypassSecureBootCheck /t REG_DWORD /d 1 /f</Path></RunSynchronousCommand>
</RunSynchronous></component></settings><settings pass="specialize"><component name="Microsoft-Windows-Deployment"><RunSynchronous>
<RunSynchronousCommand><Path>copy from the drive holding ARENA-OEM.TXT to C:\OEM</Path></RunSynchronousCommand>
</RunSynchronous></component></settings><settings pass="oobeSystem"><component name="Microsoft-Windows-Shell-Setup">
<AutoLogon><Username>Docker</Username></AutoLogon><FirstLogonCommands><SynchronousCommand><CommandLine>cmd.exe /c C:\OEM\install.bat</CommandLine></SynchronousCommand></FirstLogonCommands>
</component></settings></unattend>
XML
xorriso -as mkisofs -quiet -J -r -V ARENA_OEM -o "$RUN/oem.iso" "$RUN/media"
qemu-img create -q -f qcow2 "$RUN/disk.qcow2" 64G
started=$(now)
start_qemu 600 -m 4096 -smp 2 -drive "file=$RUN/disk.qcow2,format=qcow2,if=virtio,detect-zeroes=unmap,discard=unmap" \
    -drive "file=$IMAGES/installer.iso,media=cdrom,if=none,id=cd0,readonly=on" -device ide-cd,drive=cd0,bus=ide.1 \
    -drive "file=$RUN/oem.iso,media=cdrom,if=none,id=cd1,readonly=on" -device ide-cd,drive=cd1,bus=ide.1 \
    -boot order=cd
wait_health 480
echo "install end to end (power-on to health of the installed system): $(since "$started") s"
grep -aq "stage install: done" "$RUN/serial.log" || fail "the installer did not run"
[ "$(status "$GUEST/v1/folders")" = 401 ] || fail "GET /v1/folders without the token is not 401"
[ "$(status -H "Authorization: Bearer $TOKEN" "$GUEST/v1/folders")" = 200 ] \
    || fail "GET /v1/folders with the token is not 200"
echo "installed guest: 401 without the token, 200 with it"
qmp system_powerdown >/dev/null
wait_exit 30

echo "check: all passed"
