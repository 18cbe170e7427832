<#
.SYNOPSIS
What every setup script shares; dot-source it: . (Join-Path $PSScriptRoot 'arena-common.ps1')

.DESCRIPTION
Write-Step prints one progress line tagged with the calling script's name.
Send-Stage writes "arena-stage: NAME" to the first serial port (COM1), where
`arena vm prepare` follows the install's stages (QEMU writes the port to
serial.log); without a serial port it only says so.
Set-RegistryValue writes a registry value only when it differs (creating the
key), and says which it was, so a rerun reports "already" for each.
#>
[CmdletBinding()]
param()

Set-StrictMode -Version Latest
$ErrorActionPreference = 'Stop'

function Write-Step([string]$Message) {
    $name = [System.IO.Path]::GetFileNameWithoutExtension($MyInvocation.PSCommandPath)
    Write-Host "[$name] $Message"
}

function Send-Stage([string]$Name) {
    try {
        $port = New-Object System.IO.Ports.SerialPort 'COM1', 115200
        $port.Open()
        $port.WriteLine("arena-stage: $Name")
        $port.Close()
    } catch {
        Write-Host "no serial port for the stage line '$Name': $($_.Exception.Message)"
    }
}

function Set-RegistryValue([string]$Key, [string]$Name, $Value, [string]$Type = 'DWord') {
    # Tagged with the calling script's name, as Write-Step lines are.
    $tag = [System.IO.Path]::GetFileNameWithoutExtension($MyInvocation.PSCommandPath)
    if (-not (Test-Path -LiteralPath $Key)) {
        New-Item -Path $Key -Force | Out-Null
    }
    $current = Get-ItemProperty -LiteralPath $Key -Name $Name -ErrorAction SilentlyContinue
    if ($null -ne $current -and "$($current.$Name)" -eq "$Value") {
        Write-Host "[$tag] already $Key\$Name = $Value"
        return
    }
    New-ItemProperty -LiteralPath $Key -Name $Name -Value $Value -PropertyType $Type -Force | Out-Null
    Write-Host "[$tag] set $Key\$Name = $Value"
}
