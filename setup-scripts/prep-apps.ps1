<#
.SYNOPSIS
Installs the applications the task corpus uses, silently, from installers in the
OEM folder or downloaded from the URLs in apps.json; skips what is installed.

.DESCRIPTION
For each entry of the manifest (see apps.json for its fields): if one of its
'detect' files exists the app is skipped; otherwise the installer is taken from
<OemDir>\installers\<file> (for offline images) or downloaded (three attempts),
its SHA-256 is checked when the manifest gives one, it runs with its silent
switches, and the 'detect' file must exist afterwards. Finally the apps' folders
are put on the machine PATH, since the tasks launch 'soffice', 'vlc', 'code'
and 'chrome' by name.

Exit codes: 0 every app installed, 2 the manifest is missing or invalid or the
prompt is not elevated, 3 an app failed to download, verify or install.
#>
[CmdletBinding()]
param(
    [string]$OemDir = 'C:\OEM',
    [string]$Manifest = '',
    [string]$DownloadDir = (Join-Path $env:TEMP 'arena-apps'),
    # Install only these apps (names as in the manifest); all when empty.
    [string[]]$Only = @()
)

Set-StrictMode -Version Latest
$ErrorActionPreference = 'Stop'
# The progress bar slows Invoke-WebRequest on Windows PowerShell 5.1 by an order of magnitude.
$ProgressPreference = 'SilentlyContinue'

. (Join-Path $PSScriptRoot 'arena-common.ps1')

# A field of a manifest entry, or $Default when the entry leaves it out (strict mode
# makes a missing property an error).
function Get-Field($Entry, [string]$Name, $Default = $null) {
    $property = $Entry.PSObject.Properties[$Name]
    if ($null -eq $property -or $null -eq $property.Value) {
        return $Default
    }
    return $property.Value
}

function Get-Installer($App) {
    $file = Get-Field $App 'file'
    $offline = Join-Path (Join-Path $OemDir 'installers') $file
    if (Test-Path -LiteralPath $offline -PathType Leaf) {
        Write-Step "  using $offline"
        return $offline
    }
    $url = Get-Field $App 'url'
    if ([string]::IsNullOrEmpty($url)) {
        throw "no installer at $offline and no url to download one"
    }
    if (-not (Test-Path -LiteralPath $DownloadDir)) {
        New-Item -ItemType Directory -Path $DownloadDir | Out-Null
    }
    $target = Join-Path $DownloadDir $file
    # TLS 1.2 is not on by default for Windows PowerShell 5.1's web cmdlets.
    [Net.ServicePointManager]::SecurityProtocol = [Net.ServicePointManager]::SecurityProtocol -bor [Net.SecurityProtocolType]::Tls12
    for ($attempt = 1; $attempt -le 3; $attempt++) {
        try {
            Write-Step "  downloading $url (attempt $attempt)"
            Invoke-WebRequest -Uri $url -OutFile $target -UseBasicParsing
            return $target
        }
        catch {
            Write-Step "  download failed: $($_.Exception.Message)"
            if ($attempt -eq 3) {
                throw "cannot download $url"
            }
            Start-Sleep -Seconds (5 * $attempt)
        }
    }
}

function Install-App($App) {
    $name = Get-Field $App 'name'
    $detect = @(Get-Field $App 'detect' @())
    if ($detect.Count -eq 0) {
        throw "$name has no 'detect' paths in the manifest"
    }
    $found = @($detect | Where-Object { Test-Path -LiteralPath $_ })
    if ($found.Count -gt 0) {
        Write-Step "$name already installed ($($found[0]))"
        return
    }
    Write-Step "installing $name"
    $installer = Get-Installer $App
    $sha256 = Get-Field $App 'sha256'
    if (-not [string]::IsNullOrEmpty($sha256)) {
        $actual = (Get-FileHash -Algorithm SHA256 -LiteralPath $installer).Hash
        if ($actual -ne $sha256.ToUpperInvariant()) {
            throw "$installer has SHA-256 $actual, the manifest says $sha256"
        }
    }
    $arguments = @(Get-Field $App 'args' @())
    $kind = Get-Field $App 'kind' 'exe'
    if ($kind -eq 'msi') {
        $process = Start-Process -FilePath 'msiexec.exe' -ArgumentList (@('/i', "`"$installer`"", '/qn', '/norestart') + $arguments) -Wait -PassThru
    }
    else {
        $process = Start-Process -FilePath $installer -ArgumentList $arguments -Wait -PassThru
    }
    # 3010: installed, a reboot completes it.
    if ($process.ExitCode -ne 0 -and $process.ExitCode -ne 3010) {
        throw "the $name installer exited with $($process.ExitCode)"
    }
    $found = @($detect | Where-Object { Test-Path -LiteralPath $_ })
    if ($found.Count -eq 0) {
        throw "the $name installer finished but $($detect -join ' or ') is missing"
    }
    Write-Step "$name installed"
}

# Appends folders to the machine PATH, each once.
function Add-MachinePath([string[]]$Folders) {
    $path = [Environment]::GetEnvironmentVariable('Path', 'Machine')
    $parts = @($path -split ';' | Where-Object { $_ -ne '' })
    $added = @()
    foreach ($folder in $Folders) {
        if (@($parts | Where-Object { $_.TrimEnd('\') -ieq $folder.TrimEnd('\') }).Count -eq 0 -and (Test-Path -LiteralPath $folder)) {
            $parts += $folder
            $added += $folder
        }
    }
    if ($added.Count -gt 0) {
        [Environment]::SetEnvironmentVariable('Path', ($parts -join ';'), 'Machine')
        Write-Step "added to the machine PATH: $($added -join '; ')"
    }
    else {
        Write-Step 'machine PATH already has every app folder'
    }
}

if ([string]::IsNullOrEmpty($Manifest)) {
    $Manifest = Join-Path $OemDir 'apps.json'
}
$identity = [Security.Principal.WindowsIdentity]::GetCurrent()
if (-not (New-Object Security.Principal.WindowsPrincipal($identity)).IsInRole([Security.Principal.WindowsBuiltInRole]::Administrator)) {
    Write-Step 'ERROR: run this from an elevated PowerShell (installers write Program Files)'
    exit 2
}
if (-not (Test-Path -LiteralPath $Manifest -PathType Leaf)) {
    Write-Step "ERROR: no manifest at $Manifest"
    exit 2
}
try {
    $apps = @((Get-Content -LiteralPath $Manifest -Raw | ConvertFrom-Json).apps)
}
catch {
    Write-Step "ERROR: $Manifest is not a valid manifest: $($_.Exception.Message)"
    exit 2
}
if ($Only.Count -gt 0) {
    $unknown = @($Only | Where-Object { $apps.name -notcontains $_ })
    if ($unknown.Count -gt 0) {
        Write-Step "ERROR: not in the manifest: $($unknown -join ', ')"
        exit 2
    }
    $apps = @($apps | Where-Object { $Only -contains $_.name })
}

$failed = @()
$folders = @()
foreach ($app in $apps) {
    try {
        Install-App $app
        $folders += @(Get-Field $app 'path' @())
    }
    catch {
        # Keep going, so one broken download does not hide the state of the others.
        Write-Step "ERROR: $(Get-Field $app 'name'): $($_.Exception.Message)"
        $failed += Get-Field $app 'name'
    }
}
try {
    Add-MachinePath $folders
    # VS Code: no update prompts over the window a task works in (machine policy).
    $vscodePolicy = 'HKLM:\SOFTWARE\Policies\Microsoft\VSCode'
    if (-not (Test-Path -LiteralPath $vscodePolicy)) {
        New-Item -Path $vscodePolicy -Force | Out-Null
    }
    $mode = Get-ItemProperty -LiteralPath $vscodePolicy -Name 'UpdateMode' -ErrorAction SilentlyContinue
    if ($null -eq $mode -or $mode.UpdateMode -ne 'none') {
        New-ItemProperty -LiteralPath $vscodePolicy -Name 'UpdateMode' -Value 'none' -PropertyType String -Force | Out-Null
        Write-Step 'VS Code updates off by policy'
    }
}
catch {
    Write-Step "ERROR: $($_.Exception.Message)"
    exit 3
}
if ($failed.Count -gt 0) {
    Write-Step "ERROR: not installed: $($failed -join ', ')"
    exit 3
}
exit 0
