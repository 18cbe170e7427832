<#
.SYNOPSIS
Prepares a fresh Windows 11 image for the arena, step by step, logging to
%ProgramData%\arena\logs\setup.log (never into the OEM folder, which may be
read-only media).

.DESCRIPTION
The guest comes first, so that whatever fails later there is a guest that
answers health and doctor. The steps, in order (each its own script in this
folder, run as a child PowerShell so its exit code is its own):
  1. prep-autologon.ps1   the Docker user logs on at every boot     (required)
  2. install-guest.ps1    the guest itself, checked through its health endpoint (required)
  3. prep-automation.ps1  no updates, lock screen, screen saver, sleep, pop-ups
  4. prep-display.ps1     1440x900, or the nearest mode (recorded)
  5. prep-apps.ps1        the apps the tasks use (skipped with -SkipApps)
  6. prep-browser.ps1     DevTools on loopback for the guest to forward
A required step that fails stops the setup; a later one is logged and
reported at the end, and the rest still run.

It writes "arena-stage: oem-install" to COM1 when it starts,
"arena-stage: guest-installed" once the guest answers, and at the end
"arena-stage: oem-done" when every step succeeded or "arena-stage: oem-failed
STEP (exit code N)" naming the steps that failed: `arena vm prepare` seals the
image only after oem-done. Step by step it records its progress in
%ProgramData%\arena\setup-status.json (state running, done or failed; the step;
steps done of all; the failed steps; the log), which the guest reports as its
`setup` health component: a guest is not healthy while its setup runs.
Rerunning it is safe: every step skips what is already done.

Exit codes: 0 every step succeeded; otherwise the exit code of the required step
that failed (2 missing input, 3 a step failed, 4 the guest not healthy in time),
5 when a step's script is missing, or 6 when only later steps failed (listed in
the log's last line).
#>
[CmdletBinding()]
param(
    [string]$OemDir = 'C:\OEM',
    [string]$LogPath = '',
    [ValidateRange(1, 65535)]
    [int]$Port = 5000,
    [string]$HostNetwork = '20.20.20.0/24,10.0.2.2',
    [ValidateSet('service', 'logon-task')]
    [string]$Mode = 'service',
    [string]$UserName = 'Docker',
    [switch]$SkipApps
)

Set-StrictMode -Version Latest
$ErrorActionPreference = 'Stop'

if ([string]::IsNullOrEmpty($LogPath)) {
    $LogPath = Join-Path $env:ProgramData 'arena\logs\setup.log'
}
$logDir = Split-Path -Parent $LogPath
if (-not (Test-Path -LiteralPath $logDir)) {
    New-Item -ItemType Directory -Path $logDir -Force | Out-Null
}
. (Join-Path $PSScriptRoot 'arena-common.ps1')

function Write-Log([string]$Message) {
    $line = "$(Get-Date -Format 'yyyy-MM-dd HH:mm:ss') $Message"
    Write-Host $line
    Add-Content -LiteralPath $LogPath -Value $line
}

# Runs one step's script in a child PowerShell (the same executable as this one) and
# copies its output into the log; returns its exit code.
function Invoke-Step([string]$Script, [string[]]$Arguments) {
    $path = Join-Path $PSScriptRoot $Script
    if (-not (Test-Path -LiteralPath $path -PathType Leaf)) {
        Write-Log "step $Script is missing from $PSScriptRoot"
        return 5
    }
    Write-Log "---- $Script $($Arguments -join ' ')"
    $shell = (Get-Process -Id $PID).Path
    # A child's stderr would be turned into terminating errors by 'Stop' on
    # Windows PowerShell 5.1; its exit code is what decides here.
    $ErrorActionPreference = 'Continue'
    & $shell -NoProfile -ExecutionPolicy Bypass -File $path @Arguments 2>&1 | ForEach-Object { Write-Log "  $_" }
    $code = $LASTEXITCODE
    $ErrorActionPreference = 'Stop'
    Write-Log "---- $Script exited with $code"
    return $code
}

# The progress record the guest's `setup` health component reads, written whole
# (temporary file, then a rename) so the guest never reads half of it.
$StatusPath = Join-Path $env:ProgramData 'arena\setup-status.json'
function Write-Status([string]$State, [string]$Step, [int]$Done, [string[]]$Failed) {
    $record = [ordered]@{
        state  = $State
        step   = $Step
        done   = $Done
        total  = $steps.Count
        failed = @($Failed)
        log    = $LogPath
    }
    $json = ConvertTo-Json -InputObject $record -Compress
    $temporary = "$StatusPath.tmp"
    # UTF-8 without a byte-order mark.
    [System.IO.File]::WriteAllText($temporary, $json)
    Move-Item -LiteralPath $temporary -Destination $StatusPath -Force
}

Write-Log "arena setup starting (OEM folder $OemDir, mode $Mode, port $Port, host network $HostNetwork)"
Send-Stage 'oem-install'
$steps = @(
    @{ Script = 'prep-autologon.ps1'; Required = $true; Arguments = @('-UserName', $UserName) },
    @{ Script = 'install-guest.ps1'; Required = $true; Arguments = @('-OemDir', $OemDir, '-Port', "$Port", '-HostNetwork', $HostNetwork, '-Mode', $Mode) },
    @{ Script = 'prep-automation.ps1'; Required = $false; Arguments = @() },
    @{ Script = 'prep-display.ps1'; Required = $false; Arguments = @() },
    @{ Script = 'prep-apps.ps1'; Required = $false; Arguments = @('-OemDir', $OemDir) },
    @{ Script = 'prep-browser.ps1'; Required = $false; Arguments = @() }
)
$failed = New-Object System.Collections.Generic.List[string]
$done = 0
foreach ($step in $steps) {
    if ($SkipApps -and $step.Script -eq 'prep-apps.ps1') {
        Write-Log '---- prep-apps.ps1 skipped (-SkipApps)'
        $done++
        continue
    }
    Write-Status 'running' $step.Script $done $failed.ToArray()
    $code = Invoke-Step $step.Script $step.Arguments
    if ($code -ne 0 -and $step.Required) {
        $failed.Add("$($step.Script) (exit code $code)")
        Write-Log "arena setup FAILED at $($step.Script) with exit code $code"
        Write-Status 'failed' $step.Script $done $failed.ToArray()
        Send-Stage "oem-failed $($step.Script) (exit code $code); log $LogPath"
        exit $code
    }
    if ($code -ne 0) {
        $failed.Add("$($step.Script) (exit code $code)")
    }
    $done++
    if ($step.Script -eq 'install-guest.ps1') {
        Send-Stage 'guest-installed'
    }
}
if ($failed.Count -gt 0) {
    Write-Log "arena setup finished with the guest installed and healthy, but these steps failed: $($failed -join ', ')"
    $firstFailed = ($failed[0] -split ' ')[0]
    Write-Status 'failed' $firstFailed $done ($failed.ToArray())
    Send-Stage "oem-failed $($failed -join ', '); log $LogPath"
    exit 6
}
Write-Log 'arena setup finished: the guest is installed and healthy'
Write-Status 'done' '' $done @()
Send-Stage 'oem-done'
exit 0
