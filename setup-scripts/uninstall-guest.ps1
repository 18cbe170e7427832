<#
.SYNOPSIS
Removes what install-guest.ps1 installed: the service or logon task, the firewall
rule, the exes (arena-guest.exe and arena-guest-logon.exe) and (unless -KeepToken)
the provisioned token.

.DESCRIPTION
Each step checks first, so running it on a clean machine, or twice, is fine.

Exit codes:
  0  nothing of the guest is left (or nothing was there)
  2  not run from an elevated prompt
  3  a removal step failed
#>
[CmdletBinding()]
param(
    [string]$InstallDir = (Join-Path $env:ProgramFiles 'Arena'),
    [ValidateRange(1, 65535)]
    [int]$Port = 5000,
    [string]$ServiceName = 'ArenaGuest',
    [string]$TokenPath = 'C:\ProgramData\arena\token',
    [switch]$KeepToken
)

Set-StrictMode -Version Latest
$ErrorActionPreference = 'Stop'

$FirewallRuleName = "ArenaGuest-TCP-$Port"

. (Join-Path $PSScriptRoot 'arena-common.ps1')

$identity = [Security.Principal.WindowsIdentity]::GetCurrent()
if (-not (New-Object Security.Principal.WindowsPrincipal($identity)).IsInRole([Security.Principal.WindowsBuiltInRole]::Administrator)) {
    Write-Step 'ERROR: run this from an elevated PowerShell'
    exit 2
}

$exe = Join-Path $InstallDir 'arena-guest.exe'
try {
    if (Test-Path -LiteralPath $exe -PathType Leaf) {
        if ($null -ne (Get-Service -Name $ServiceName -ErrorAction SilentlyContinue)) {
            & $exe service uninstall --name $ServiceName
            if ($LASTEXITCODE -ne 0) {
                throw "arena-guest.exe service uninstall exited with $LASTEXITCODE"
            }
            Write-Step "service $ServiceName removed"
        }
        else {
            Write-Step "no service $ServiceName"
        }
        # The logon task may never have been installed; a failure here is only reported,
        # since the exe is the one that knows the task's name.
        & $exe logon-task uninstall
        if ($LASTEXITCODE -ne 0) {
            Write-Step "logon-task uninstall exited with $LASTEXITCODE (no task installed?)"
        }
        # The logon task's launcher first: it would start the server again.
        $launcher = Join-Path $InstallDir 'arena-guest-logon.exe'
        foreach ($process in @(@('arena-guest-logon', $launcher), @('arena-guest', $exe))) {
            Get-Process -Name $process[0] -ErrorAction SilentlyContinue |
                Where-Object { $_.Path -eq $process[1] } |
                ForEach-Object { Write-Step "stopping $($process[0]).exe pid $($_.Id)"; Stop-Process -Id $_.Id -Force }
        }
    }
    elseif ($null -ne (Get-Service -Name $ServiceName -ErrorAction SilentlyContinue)) {
        # The exe is gone but its service is not: remove the registration directly.
        & sc.exe delete $ServiceName | Out-Null
        Write-Step "service $ServiceName deleted with sc.exe (its exe was already gone)"
    }

    if ($null -ne (Get-NetFirewallRule -Name $FirewallRuleName -ErrorAction SilentlyContinue)) {
        Remove-NetFirewallRule -Name $FirewallRuleName
        Write-Step "firewall rule $FirewallRuleName removed"
    }
    else {
        Write-Step "no firewall rule $FirewallRuleName"
    }

    if (Test-Path -LiteralPath $InstallDir) {
        Remove-Item -LiteralPath $InstallDir -Recurse -Force
        Write-Step "removed $InstallDir"
    }

    $tokenDir = Split-Path -Parent $TokenPath
    if (-not $KeepToken -and (Test-Path -LiteralPath $tokenDir)) {
        Remove-Item -LiteralPath $tokenDir -Recurse -Force
        Write-Step "removed $tokenDir"
    }
}
catch {
    Write-Step "ERROR: $($_.Exception.Message)"
    exit 3
}
Write-Step 'done'
exit 0
