<#
.SYNOPSIS
Lets Chrome and Edge be driven over the DevTools protocol on loopback port 1337,
which the guest forwards to the host at /v1/browser/*.

.DESCRIPTION
Upstream WAA ran a caddy reverse proxy from port 9222 to the browsers' DevTools
port 1337. Here no extra program is needed: arena-guest.exe itself forwards
/v1/browser/* (behind its token) to 127.0.0.1:<--cdp-port, default 1337>, so the
DevTools port stays on loopback and never opens in the firewall.

Tasks start the browsers with --remote-debugging-port=1337. This script:
  - allows remote debugging by policy (RemoteDebuggingAllowed), so a managed
    policy elsewhere cannot switch it off;
  - gives both browsers a non-default profile folder (UserDataDir policy):
    Chrome 136 and later ignore --remote-debugging-port on the default profile
    folder, which made the port silently never open;
  - starts nothing itself: the tasks' own launch commands carry the flag.

Exit codes: 0 done, 2 not elevated, 3 a policy could not be written.
#>
[CmdletBinding()]
param(
    # Profile folders, in the policy's own variable syntax (expanded per user by the browser).
    [string]$ChromeUserDataDir = '${local_app_data}\Arena\Chrome',
    [string]$EdgeUserDataDir = '${local_app_data}\Arena\Edge'
)

Set-StrictMode -Version Latest
$ErrorActionPreference = 'Stop'

. (Join-Path $PSScriptRoot 'arena-common.ps1')

$identity = [Security.Principal.WindowsIdentity]::GetCurrent()
if (-not (New-Object Security.Principal.WindowsPrincipal($identity)).IsInRole([Security.Principal.WindowsBuiltInRole]::Administrator)) {
    Write-Step 'ERROR: run this from an elevated PowerShell (it writes HKLM policies)'
    exit 2
}

try {
    $chrome = 'HKLM:\SOFTWARE\Policies\Google\Chrome'
    Set-RegistryValue $chrome 'RemoteDebuggingAllowed' 1
    Set-RegistryValue $chrome 'UserDataDir' $ChromeUserDataDir 'String'
    # DevTools must stay usable: a policy of 2 would disable the protocol as well.
    Set-RegistryValue $chrome 'DeveloperToolsAvailability' 1

    $edge = 'HKLM:\SOFTWARE\Policies\Microsoft\Edge'
    Set-RegistryValue $edge 'RemoteDebuggingAllowed' 1
    Set-RegistryValue $edge 'UserDataDir' $EdgeUserDataDir 'String'
    Set-RegistryValue $edge 'DeveloperToolsAvailability' 1
}
catch {
    Write-Step "ERROR: $($_.Exception.Message)"
    exit 3
}
exit 0
