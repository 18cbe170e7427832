<#
.SYNOPSIS
Makes Windows log the benchmark user (Docker) on automatically at every boot.

.DESCRIPTION
The guest drives the interactive desktop, so a session must exist after every
reboot without anyone typing a password. The answer file's AutoLogon has a
LogonCount that runs out; the Winlogon values set here do not.

Exit codes: 0 done (or already so), 2 the user does not exist or the prompt is
not elevated, 3 a registry write failed.
#>
[CmdletBinding()]
param(
    [string]$UserName = 'Docker',
    # Only when given is DefaultPassword written: the answer file (dockur's included)
    # already stored the password as an LSA secret, which an empty DefaultPassword
    # value would override and break.
    [string]$Password = ''
)

Set-StrictMode -Version Latest
$ErrorActionPreference = 'Stop'

$Winlogon = 'HKLM:\SOFTWARE\Microsoft\Windows NT\CurrentVersion\Winlogon'

. (Join-Path $PSScriptRoot 'arena-common.ps1')

# Sets a string value only when it differs, and says which it was.
function Set-WinlogonValue([string]$Name, [string]$Value, [switch]$Secret) {
    $current = (Get-ItemProperty -Path $Winlogon -Name $Name -ErrorAction SilentlyContinue)
    $currentValue = if ($null -ne $current) { [string]$current.$Name } else { $null }
    $shown = if ($Secret) { '<hidden>' } else { $Value }
    if ($currentValue -ceq $Value) {
        Write-Step "$Name already $shown"
        return
    }
    New-ItemProperty -Path $Winlogon -Name $Name -Value $Value -PropertyType String -Force | Out-Null
    Write-Step "$Name set to $shown"
}

$identity = [Security.Principal.WindowsIdentity]::GetCurrent()
if (-not (New-Object Security.Principal.WindowsPrincipal($identity)).IsInRole([Security.Principal.WindowsBuiltInRole]::Administrator)) {
    Write-Step 'ERROR: run this from an elevated PowerShell (it writes HKLM)'
    exit 2
}
if ($null -eq (Get-LocalUser -Name $UserName -ErrorAction SilentlyContinue)) {
    Write-Step "ERROR: there is no local user $UserName (the answer file creates it)"
    exit 2
}

try {
    Set-WinlogonValue 'AutoAdminLogon' '1'
    Set-WinlogonValue 'DefaultUserName' $UserName
    Set-WinlogonValue 'DefaultDomainName' $env:COMPUTERNAME
    if ($PSBoundParameters.ContainsKey('Password')) {
        Set-WinlogonValue 'DefaultPassword' $Password -Secret
    }
    # A count left by the answer file would switch auto-logon off once it reaches zero.
    if ($null -ne (Get-ItemProperty -Path $Winlogon -Name 'AutoLogonCount' -ErrorAction SilentlyContinue)) {
        Remove-ItemProperty -Path $Winlogon -Name 'AutoLogonCount'
        Write-Step 'AutoLogonCount removed (auto-logon no longer runs out)'
    }
    # Windows 11 hides password sign-in for local accounts behind "passwordless"
    # unless this is 0, and auto-logon then stops working.
    $passwordLess = 'HKLM:\SOFTWARE\Microsoft\Windows NT\CurrentVersion\PasswordLess\Device'
    if (Test-Path $passwordLess) {
        $value = Get-ItemProperty -Path $passwordLess -Name 'DevicePasswordLessBuildVersion' -ErrorAction SilentlyContinue
        if ($null -eq $value -or $value.DevicePasswordLessBuildVersion -ne 0) {
            New-ItemProperty -Path $passwordLess -Name 'DevicePasswordLessBuildVersion' -Value 0 -PropertyType DWord -Force | Out-Null
            Write-Step 'DevicePasswordLessBuildVersion set to 0'
        }
    }
}
catch {
    Write-Step "ERROR: $($_.Exception.Message)"
    exit 3
}
exit 0
