<#
.SYNOPSIS
Installs arena-guest.exe into this Windows image and checks that it answers.

.DESCRIPTION
Copies the guest's two exes from the OEM folder to Program Files (arena-guest.exe,
the server, and arena-guest-logon.exe, the logon task's launcher, which must sit
beside it), provisions the API token
into a file only SYSTEM and Administrators can read, opens the guest's port in
the firewall for the host-side network only, registers the guest to start in
the interactive user's session (the exe's own Windows service by default, or a
logon task as upstream WAA does), and then polls the guest's health endpoint,
printing every component as it comes up.

Running it twice changes nothing: every step looks before it acts.

Exit codes (setup.ps1 and install.bat pass them on):
  0  installed, and the guest reports every component up
  2  a required input is missing (an exe, the token, or an elevated prompt)
  3  an install step failed (copy, ACL, firewall, service or task registration)
  4  installed, but the guest was not healthy within -HealthTimeoutSeconds
#>
[CmdletBinding()]
param(
    # Where dockur/windows put the staged folder (arena prep stage --out).
    [string]$OemDir = 'C:\OEM',
    [string]$InstallDir = (Join-Path $env:ProgramFiles 'Arena'),
    [ValidateRange(1, 65535)]
    [int]$Port = 5000,
    # Who may reach the port, comma-separated: dockur's bridge is 20.20.20.0/24 (the host
    # side is 20.20.20.1); a VM that `arena vm` runs on QEMU's user network is reached from 10.0.2.2.
    [string]$HostNetwork = '20.20.20.0/24,10.0.2.2',
    [ValidateSet('service', 'logon-task')]
    [string]$Mode = 'service',
    [string]$ServiceName = 'ArenaGuest',
    [string]$TokenPath = 'C:\ProgramData\arena\token',
    [ValidateRange(1, 3600)]
    [int]$HealthTimeoutSeconds = 300,
    # Leave the OEM copy of the token in place (by default it is deleted once provisioned,
    # because C:\OEM is readable by every local user).
    [switch]$KeepOemToken
)

Set-StrictMode -Version Latest
$ErrorActionPreference = 'Stop'

$ExitMissingInput = 2
$ExitStepFailed = 3
$ExitNotHealthy = 4

# The firewall rule is found again by this Name (not its DisplayName): upstream looked
# rules up by -Name but created them by -DisplayName, so every rerun added a duplicate.
$FirewallRuleName = "ArenaGuest-TCP-$Port"
# Well-known SIDs, so the ACL is right on every display language of Windows.
$SystemSid = 'S-1-5-18'
$AdministratorsSid = 'S-1-5-32-544'

. (Join-Path $PSScriptRoot 'arena-common.ps1')

function Stop-WithCode([int]$Code, [string]$Message) {
    Write-Host "[install-guest] ERROR: $Message"
    exit $Code
}

function Test-Elevated {
    $identity = [Security.Principal.WindowsIdentity]::GetCurrent()
    $principal = New-Object Security.Principal.WindowsPrincipal($identity)
    return $principal.IsInRole([Security.Principal.WindowsBuiltInRole]::Administrator)
}

# Runs the guest exe with arguments and fails the install when it exits non-zero.
function Invoke-Guest([string]$Exe, [string[]]$Arguments) {
    Write-Step "running arena-guest.exe $($Arguments -join ' ')"
    & $Exe @Arguments
    if ($LASTEXITCODE -ne 0) {
        Stop-WithCode $ExitStepFailed "arena-guest.exe $($Arguments -join ' ') exited with $LASTEXITCODE"
    }
}

# Whether a folder's ACL is exactly: not inheriting, full control for SYSTEM and Administrators, nobody else.
function Test-PrivateAcl([string]$Path) {
    $acl = Get-Acl -Path $Path
    if (-not $acl.AreAccessRulesProtected) {
        return $false
    }
    $sids = @($acl.Access | ForEach-Object {
            $_.IdentityReference.Translate([Security.Principal.SecurityIdentifier]).Value
        } | Sort-Object -Unique)
    $expected = @($AdministratorsSid, $SystemSid) | Sort-Object
    return (($sids -join ',') -eq ($expected -join ','))
}

function Set-PrivateAcl([string]$Path) {
    # /inheritance:r drops what C:\ProgramData would hand down (Users: read);
    # /grant:r replaces any grant for these two with full control, inherited by the files inside.
    & icacls.exe $Path /inheritance:r /grant:r "*${SystemSid}:(OI)(CI)F" "*${AdministratorsSid}:(OI)(CI)F" | Out-Null
    if ($LASTEXITCODE -ne 0) {
        Stop-WithCode $ExitStepFailed "icacls on $Path exited with $LASTEXITCODE"
    }
}

function Get-FileSha256([string]$Path) {
    return (Get-FileHash -Algorithm SHA256 -Path $Path).Hash
}

# ---- 0. inputs ----------------------------------------------------------------

if (-not (Test-Elevated)) {
    Stop-WithCode $ExitMissingInput 'run this from an elevated PowerShell (it installs a service and a firewall rule)'
}
# The server and the logon task's launcher ship together: `logon-task install` refuses
# to register a task whose launcher is not beside arena-guest.exe.
$ExeNames = @('arena-guest.exe', 'arena-guest-logon.exe')
$sourceToken = Join-Path $OemDir 'arena-token'
$installedExe = Join-Path $InstallDir 'arena-guest.exe'
$installedLauncher = Join-Path $InstallDir 'arena-guest-logon.exe'
foreach ($name in $ExeNames) {
    if (-not (Test-Path -LiteralPath (Join-Path $OemDir $name) -PathType Leaf) -and
        -not (Test-Path -LiteralPath (Join-Path $InstallDir $name) -PathType Leaf)) {
        Stop-WithCode $ExitMissingInput "no $name in $OemDir (stage the folder with: arena prep stage --out DIR)"
    }
}
if (-not (Test-Path -LiteralPath $sourceToken -PathType Leaf) -and -not (Test-Path -LiteralPath $TokenPath -PathType Leaf)) {
    Stop-WithCode $ExitMissingInput "no arena-token in $OemDir and none installed at $TokenPath"
}

try {
    # ---- 1. the exes ----------------------------------------------------------
    $changed = @()
    foreach ($name in $ExeNames) {
        $source = Join-Path $OemDir $name
        $installed = Join-Path $InstallDir $name
        if (-not (Test-Path -LiteralPath $source -PathType Leaf)) {
            Write-Step "no $name in $OemDir; keeping the installed $installed"
        }
        elseif ((Test-Path -LiteralPath $installed -PathType Leaf) -and
            ((Get-FileSha256 $source) -eq (Get-FileSha256 $installed))) {
            Write-Step "$name already installed at $installed (same SHA-256)"
        }
        else {
            $changed += $name
        }
    }
    if ($changed.Count -gt 0) {
        # A running guest holds its exes open: stop it before replacing the files, the
        # launcher first (it would start the server again).
        $service = Get-Service -Name $ServiceName -ErrorAction SilentlyContinue
        if ($null -ne $service -and $service.Status -ne 'Stopped') {
            Write-Step "stopping service $ServiceName to replace its exe"
            Stop-Service -Name $ServiceName -Force
        }
        foreach ($process in @(@('arena-guest-logon', $installedLauncher), @('arena-guest', $installedExe))) {
            Get-Process -Name $process[0] -ErrorAction SilentlyContinue |
                Where-Object { $_.Path -eq $process[1] } |
                ForEach-Object { Write-Step "stopping $($process[0]).exe pid $($_.Id)"; Stop-Process -Id $_.Id -Force }
        }
        if (-not (Test-Path -LiteralPath $InstallDir)) {
            New-Item -ItemType Directory -Path $InstallDir | Out-Null
        }
        foreach ($name in $changed) {
            Copy-Item -LiteralPath (Join-Path $OemDir $name) -Destination (Join-Path $InstallDir $name) -Force
            Write-Step "copied $name to $InstallDir"
        }
    }

    # ---- 2. the token ---------------------------------------------------------
    $tokenDir = Split-Path -Parent $TokenPath
    if (-not (Test-Path -LiteralPath $tokenDir)) {
        New-Item -ItemType Directory -Path $tokenDir | Out-Null
        Write-Step "created $tokenDir"
    }
    if (Test-PrivateAcl $tokenDir) {
        Write-Step "$tokenDir is already readable by SYSTEM and Administrators only"
    }
    else {
        Set-PrivateAcl $tokenDir
        Write-Step "restricted $tokenDir to SYSTEM and Administrators"
    }
    if (Test-Path -LiteralPath $sourceToken -PathType Leaf) {
        $token = (Get-Content -LiteralPath $sourceToken -TotalCount 1).Trim()
        if ($token.Length -lt 16 -or $token -match '\s') {
            Stop-WithCode $ExitMissingInput "$sourceToken does not hold a token (one line, no spaces, at least 16 characters)"
        }
        $current = $null
        if (Test-Path -LiteralPath $TokenPath -PathType Leaf) {
            $current = (Get-Content -LiteralPath $TokenPath -TotalCount 1).Trim()
        }
        if ($current -eq $token) {
            Write-Step "token already provisioned at $TokenPath"
        }
        else {
            # UTF-8 without a byte-order mark: the guest trims whitespace, not a BOM,
            # and Set-Content -Encoding UTF8 on Windows PowerShell 5.1 writes one.
            [IO.File]::WriteAllText($TokenPath, "$token`n", (New-Object Text.UTF8Encoding($false)))
            Write-Step "token provisioned at $TokenPath"
        }
        if (-not $KeepOemToken) {
            Remove-Item -LiteralPath $sourceToken -Force
            Write-Step "removed the OEM copy $sourceToken (every local user can read C:\OEM)"
        }
    }
    else {
        Write-Step "no token in $OemDir; keeping the provisioned $TokenPath"
    }
    # The file inherits the folder's ACL, but one copied in earlier by hand may not.
    if (-not (Test-PrivateAcl $TokenPath)) {
        Set-PrivateAcl $TokenPath
        Write-Step "restricted $TokenPath to SYSTEM and Administrators"
    }

    # ---- 3. the firewall ------------------------------------------------------
    $rule = Get-NetFirewallRule -Name $FirewallRuleName -ErrorAction SilentlyContinue
    $ruleOk = $false
    if ($null -ne $rule) {
        $app = ($rule | Get-NetFirewallApplicationFilter).Program
        $ports = ($rule | Get-NetFirewallPortFilter).LocalPort
        $remote = @(($rule | Get-NetFirewallAddressFilter).RemoteAddress) -join ','
        $ruleOk = ($app -eq $installedExe) -and ("$ports" -eq "$Port") -and ($remote -eq $HostNetwork) -and ($rule.Enabled -eq 'True')
        if (-not $ruleOk) {
            Write-Step "firewall rule $FirewallRuleName differs (program $app, port $ports, from $remote): replacing it"
            Remove-NetFirewallRule -Name $FirewallRuleName
        }
    }
    if ($ruleOk) {
        Write-Step "firewall rule $FirewallRuleName already allows TCP $Port from $HostNetwork"
    }
    else {
        New-NetFirewallRule -Name $FirewallRuleName -DisplayName "Arena guest (TCP $Port)" -Direction Inbound `
            -Action Allow -Protocol TCP -LocalPort $Port -Program $installedExe -RemoteAddress ($HostNetwork -split ',') -Profile Any | Out-Null
        Write-Step "firewall rule $FirewallRuleName allows TCP $Port to $installedExe from $HostNetwork"
    }

    # ---- 4. start in the user's session -------------------------------------
    $serveOptions = @('--bind', '0.0.0.0', '--port', "$Port", '--token-file', $TokenPath)
    if ($Mode -eq 'service') {
        # The exe's own install is idempotent: it updates an existing registration. Its worker
        # runs with the user's full (elevated) token by default, which is what lets it read
        # the token file above with UAC on; see README.md.
        Invoke-Guest $installedExe (@('service', 'install', '--name', $ServiceName) + $serveOptions)
        $service = Get-Service -Name $ServiceName
        if ($service.Status -ne 'Running') {
            Write-Step "starting service $ServiceName"
            Start-Service -Name $ServiceName
        }
        else {
            Write-Step "service $ServiceName is running"
        }
    }
    else {
        # Switching from the service to a logon task: two guests would fight over the port.
        if ($null -ne (Get-Service -Name $ServiceName -ErrorAction SilentlyContinue)) {
            Invoke-Guest $installedExe @('service', 'uninstall', '--name', $ServiceName)
        }
        Invoke-Guest $installedExe (@('logon-task', 'install') + $serveOptions)
        # The task runs at the next logon; this logon gets the guest now, started by the
        # task itself so it runs exactly as it will then (no console window, no time
        # limit, normal priority, output in C:\ProgramData\arena\logon-task.log).
        $running = Get-Process -Name 'arena-guest' -ErrorAction SilentlyContinue | Where-Object { $_.Path -eq $installedExe }
        if ($null -eq $running) {
            Write-Step 'starting the logon task ArenaGuest in this session'
            Start-ScheduledTask -TaskName 'ArenaGuest'
        }
        else {
            Write-Step 'arena-guest.exe is already running in this session'
        }
    }
}
catch {
    Stop-WithCode $ExitStepFailed "$($_.Exception.Message) (at line $($_.InvocationInfo.ScriptLineNumber))"
}

# ---- 5. verify: poll /v1/health (it needs no token) ------------------------------

# HttpClient hands back 503 answers (the guest's "not ready yet") instead of throwing
# as Invoke-WebRequest does on Windows PowerShell 5.1.
Add-Type -AssemblyName System.Net.Http
$http = New-Object System.Net.Http.HttpClient
$http.Timeout = [TimeSpan]::FromSeconds(10)
$url = "http://127.0.0.1:$Port/v1/health"
$deadline = (Get-Date).AddSeconds($HealthTimeoutSeconds)
$seen = @{}
$lastError = ''
$report = $null
Write-Step "waiting up to $HealthTimeoutSeconds s for $url"
while ((Get-Date) -lt $deadline) {
    try {
        $body = $http.GetAsync($url).GetAwaiter().GetResult().Content.ReadAsStringAsync().GetAwaiter().GetResult()
        $report = $body | ConvertFrom-Json
        foreach ($component in @($report.components)) {
            $state = if ($component.ok) { 'ok' } else { 'fail' }
            if ($seen[$component.component] -ne $state) {
                $seen[$component.component] = $state
                Write-Step ("  {0,-14} {1,-4} {2}" -f $component.component, $state, $component.detail)
            }
        }
        # The setup component is down while setup.ps1 runs, and this script is one of its steps.
        $down = @($report.components | Where-Object { -not $_.ok -and $_.component -ne 'setup' })
        if (@($report.components).Count -gt 0 -and $down.Count -eq 0) {
            Write-Step "guest ready: version $($report.version), backend $($report.backend), token required: $($report.auth_required)"
            exit 0
        }
    }
    catch {
        $message = $_.Exception.GetBaseException().Message
        if ($message -ne $lastError) {
            Write-Step "  not answering yet: $message"
            $lastError = $message
        }
    }
    Start-Sleep -Seconds 2
}
if ($null -eq $report) {
    Stop-WithCode $ExitNotHealthy "the guest never answered on $url ($lastError); see the service's event log or run arena-guest.exe service status --name $ServiceName"
}
$missing = @($report.components | Where-Object { -not $_.ok -and $_.component -ne 'setup' } | ForEach-Object { "$($_.component) ($($_.detail))" })
Stop-WithCode $ExitNotHealthy "the guest is not healthy after $HealthTimeoutSeconds s; still down: $($missing -join '; ')"
