<#
.SYNOPSIS
Sets the primary display to a fixed resolution (1440x900, as upstream WAA's image).

.DESCRIPTION
Screenshots, click coordinates and the Set-of-Marks boxes of recorded
trajectories all assume one size, so the image pins it. The change goes
through ChangeDisplaySettingsEx (tested first with CDS_TEST, then stored for
every user with CDS_UPDATEREGISTRY | CDS_GLOBAL). Run it in the interactive
session: a service in session 0 has no display to change.

When the size is not a mode of the display adapter (OVMF's GOP-only display
offers a few fixed ones), the nearest mode is set instead (least squared
distance in width and height) and recorded in -RecordPath, so a run can say
which size its screenshots have.

Exit codes: 0 the display has the size (or the nearest one, recorded), 2 the
adapter lists no mode at all, 3 the change failed.
#>
[CmdletBinding()]
param(
    [ValidateRange(640, 7680)]
    [int]$Width = 1440,
    [ValidateRange(480, 4320)]
    [int]$Height = 900,
    # Where the size actually set is written ("WIDTHxHEIGHT", one line).
    [string]$RecordPath = (Join-Path $env:ProgramData 'arena\display.txt')
)

Set-StrictMode -Version Latest
$ErrorActionPreference = 'Stop'

. (Join-Path $PSScriptRoot 'arena-common.ps1')

# DEVMODEW as user32 declares it (display half of the unions), 220 bytes.
$source = @'
using System;
using System.Runtime.InteropServices;

public static class ArenaDisplay {
    [StructLayout(LayoutKind.Sequential, CharSet = CharSet.Unicode)]
    public struct DEVMODE {
        [MarshalAs(UnmanagedType.ByValTStr, SizeConst = 32)] public string dmDeviceName;
        public short dmSpecVersion;
        public short dmDriverVersion;
        public short dmSize;
        public short dmDriverExtra;
        public int dmFields;
        public int dmPositionX;
        public int dmPositionY;
        public int dmDisplayOrientation;
        public int dmDisplayFixedOutput;
        public short dmColor;
        public short dmDuplex;
        public short dmYResolution;
        public short dmTTOption;
        public short dmCollate;
        [MarshalAs(UnmanagedType.ByValTStr, SizeConst = 32)] public string dmFormName;
        public short dmLogPixels;
        public int dmBitsPerPel;
        public int dmPelsWidth;
        public int dmPelsHeight;
        public int dmDisplayFlags;
        public int dmDisplayFrequency;
        public int dmICMMethod;
        public int dmICMIntent;
        public int dmMediaType;
        public int dmDitherType;
        public int dmReserved1;
        public int dmReserved2;
        public int dmPanningWidth;
        public int dmPanningHeight;
    }

    public const int ENUM_CURRENT_SETTINGS = -1;
    public const int DM_PELSWIDTH = 0x80000;
    public const int DM_PELSHEIGHT = 0x100000;
    public const uint CDS_UPDATEREGISTRY = 0x1;
    public const uint CDS_TEST = 0x2;
    public const uint CDS_GLOBAL = 0x8;

    [DllImport("user32.dll", CharSet = CharSet.Unicode)]
    public static extern bool EnumDisplaySettingsW(string deviceName, int modeNum, ref DEVMODE devMode);

    [DllImport("user32.dll", CharSet = CharSet.Unicode)]
    public static extern int ChangeDisplaySettingsExW(string deviceName, ref DEVMODE devMode, IntPtr hwnd, uint flags, IntPtr lParam);

    public static DEVMODE Blank() {
        DEVMODE mode = new DEVMODE();
        mode.dmDeviceName = new string('\0', 32);
        mode.dmFormName = new string('\0', 32);
        mode.dmSize = (short)Marshal.SizeOf(typeof(DEVMODE));
        return mode;
    }
}
'@
# Add-Type fails on a second run in the same session if the type exists already.
if (-not ('ArenaDisplay' -as [type])) {
    Add-Type -TypeDefinition $source
}

$current = [ArenaDisplay]::Blank()
if (-not [ArenaDisplay]::EnumDisplaySettingsW($null, [ArenaDisplay]::ENUM_CURRENT_SETTINGS, [ref]$current)) {
    Write-Step 'ERROR: cannot read the current display mode (is this the interactive session?)'
    exit 3
}
if ($current.dmPelsWidth -eq $Width -and $current.dmPelsHeight -eq $Height) {
    Write-Step "display already ${Width}x${Height}"
    exit 0
}
Write-Step "display is $($current.dmPelsWidth)x$($current.dmPelsHeight); changing to ${Width}x${Height}"

$wanted = $current
$wanted.dmPelsWidth = $Width
$wanted.dmPelsHeight = $Height
$wanted.dmFields = [ArenaDisplay]::DM_PELSWIDTH -bor [ArenaDisplay]::DM_PELSHEIGHT
$test = [ArenaDisplay]::ChangeDisplaySettingsExW($null, [ref]$wanted, [IntPtr]::Zero, [ArenaDisplay]::CDS_TEST, [IntPtr]::Zero)
if ($test -ne 0) {
    $modes = New-Object System.Collections.Generic.List[string]
    $mode = [ArenaDisplay]::Blank()
    $index = 0
    $best = $null
    $bestDistance = [long]::MaxValue
    while ([ArenaDisplay]::EnumDisplaySettingsW($null, $index, [ref]$mode)) {
        $name = "$($mode.dmPelsWidth)x$($mode.dmPelsHeight)"
        if (-not $modes.Contains($name)) {
            $modes.Add($name)
        }
        $dw = [long]$mode.dmPelsWidth - $Width
        $dh = [long]$mode.dmPelsHeight - $Height
        $distance = $dw * $dw + $dh * $dh
        if ($distance -lt $bestDistance) {
            $bestDistance = $distance
            $best = $mode
        }
        $index++
    }
    if ($null -eq $best) {
        Write-Step "ERROR: ${Width}x${Height} is not a mode of this display (test answered $test) and it lists no modes"
        exit 2
    }
    Write-Step "${Width}x${Height} is not a mode of this display (modes: $($modes -join ', ')); using the nearest, $($best.dmPelsWidth)x$($best.dmPelsHeight)"
    $Width = [int]$best.dmPelsWidth
    $Height = [int]$best.dmPelsHeight
    $wanted.dmPelsWidth = $Width
    $wanted.dmPelsHeight = $Height
}
$recordDir = Split-Path -Parent $RecordPath
if (-not (Test-Path -LiteralPath $recordDir)) {
    New-Item -ItemType Directory -Path $recordDir -Force | Out-Null
}
Set-Content -LiteralPath $RecordPath -Value "${Width}x${Height}"
$flags = [ArenaDisplay]::CDS_UPDATEREGISTRY -bor [ArenaDisplay]::CDS_GLOBAL
$result = [ArenaDisplay]::ChangeDisplaySettingsExW($null, [ref]$wanted, [IntPtr]::Zero, $flags, [IntPtr]::Zero)
# 0 is DISP_CHANGE_SUCCESSFUL, 1 DISP_CHANGE_RESTART (applied after a reboot).
switch ($result) {
    0 { Write-Step "display set to ${Width}x${Height}"; exit 0 }
    1 { Write-Step "display set to ${Width}x${Height} from the next boot"; exit 0 }
    default { Write-Step "ERROR: ChangeDisplaySettingsEx answered $result"; exit 3 }
}
