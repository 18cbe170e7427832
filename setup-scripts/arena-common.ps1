<#
.SYNOPSIS
What every setup script shares; dot-source it: . (Join-Path $PSScriptRoot 'arena-common.ps1')

.DESCRIPTION
Write-Step prints one progress line tagged with the calling script's name.
Send-Stage writes "arena-stage: NAME" to the first serial port (COM1), where
`arena vm prepare` follows the install's stages (QEMU writes the port to
serial.log); without a serial port it only says so.
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
