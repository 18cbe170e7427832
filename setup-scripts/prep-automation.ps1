<#
.SYNOPSIS
Turns off what breaks unattended desktop automation: Windows Update, Defender's
real-time protection (and excludes the guest's folders from its scans), SmartScreen, Smart App Control, password expiry, the lock
screen, the screen saver, sleep, UAC's secure desktop, first-run pop-ups,
focus-stealing notifications, Store updates and OneDrive's setup at logon; shows
file extensions; draws the first logon's screen as upstream's image does (no
unsupported-hardware watermark, no Task View, Widgets, Chat or Copilot button).

.DESCRIPTION
Run it in the benchmark user's session (setup.ps1 does, at first logon): the
per-user settings go to that user's HKCU. Every registry value is compared
before it is written, so a rerun reports "already" for each.

Exit codes: 0 done, 2 not elevated, 3 a setting could not be applied.
#>
[CmdletBinding()]
param(
    # Keep Windows Update running (for an image that is patched before it is frozen).
    [switch]$KeepWindowsUpdate
)

Set-StrictMode -Version Latest
$ErrorActionPreference = 'Stop'

. (Join-Path $PSScriptRoot 'arena-common.ps1')

# Runs powercfg; it only sets values, so running it again with the same values changes nothing.
function Invoke-PowerCfg([string[]]$Arguments) {
    & powercfg.exe @Arguments
    if ($LASTEXITCODE -ne 0) {
        throw "powercfg $($Arguments -join ' ') exited with $LASTEXITCODE"
    }
}

$identity = [Security.Principal.WindowsIdentity]::GetCurrent()
if (-not (New-Object Security.Principal.WindowsPrincipal($identity)).IsInRole([Security.Principal.WindowsBuiltInRole]::Administrator)) {
    Write-Step 'ERROR: run this from an elevated PowerShell (it writes HKLM and services)'
    exit 2
}

try {
    # Windows Update: a reboot or a "restart now" toast in the middle of an episode ruins it.
    if (-not $KeepWindowsUpdate) {
        Set-RegistryValue 'HKLM:\SOFTWARE\Policies\Microsoft\Windows\WindowsUpdate\AU' 'NoAutoUpdate' 1
        Set-RegistryValue 'HKLM:\SOFTWARE\Policies\Microsoft\Windows\WindowsUpdate\AU' 'NoAutoRebootWithLoggedOnUsers' 1
        Set-RegistryValue 'HKLM:\SOFTWARE\Policies\Microsoft\Windows\WindowsUpdate' 'SetDisableUXWUAccess' 1
        $wu = Get-Service -Name 'wuauserv'
        if ($wu.StartType -ne 'Disabled') {
            Stop-Service -Name 'wuauserv' -Force
            Set-Service -Name 'wuauserv' -StartupType Disabled
            Write-Step 'wuauserv stopped and disabled'
        }
        else {
            Write-Step 'already wuauserv disabled'
        }
    }

    # Defender's real-time protection, SmartScreen and Smart App Control: the answer file of
    # `arena vm prepare` writes the same policies in its specialize pass; here for images
    # made another way. Tamper Protection may keep real-time protection on regardless
    # (docs/vm.md); a task's downloads and programs must not be held up or blocked.
    Set-RegistryValue 'HKLM:\SOFTWARE\Policies\Microsoft\Windows Defender\Real-Time Protection' 'DisableRealtimeMonitoring' 1
    # Defender never scans the guest's exes, its data or the OEM folder (path exclusions by
    # policy: Microsoft Learn, "Configure and validate exclusions based on file extension and
    # folder location"; each value named by its path, 0), whatever Tamper Protection leaves on.
    Set-RegistryValue 'HKLM:\SOFTWARE\Policies\Microsoft\Windows Defender\Exclusions' 'Exclusions_Paths' 1
    foreach ($excluded in @((Join-Path $env:ProgramFiles 'Arena'), (Join-Path $env:ProgramData 'arena'), 'C:\OEM')) {
        Set-RegistryValue 'HKLM:\SOFTWARE\Policies\Microsoft\Windows Defender\Exclusions\Paths' $excluded 0
    }
    Set-RegistryValue 'HKLM:\SOFTWARE\Policies\Microsoft\Windows\System' 'EnableSmartScreen' 0
    Set-RegistryValue 'HKLM:\SYSTEM\CurrentControlSet\Control\CI\Policy' 'VerifiedAndReputablePolicyState' 0
    # Passwords never expire (Windows' default maximum age is 42 days, after which the
    # auto-logon stops at "The user's password must be changed").
    & net.exe accounts /maxpwage:unlimited | Out-Null
    if ($LASTEXITCODE -ne 0) {
        throw "net accounts /maxpwage:unlimited exited with $LASTEXITCODE"
    }
    Write-Step 'passwords never expire (net accounts /maxpwage:unlimited)'

    # Lock screen and sign-in on wake: the guest cannot see or type into the secure desktop.
    Set-RegistryValue 'HKLM:\SOFTWARE\Policies\Microsoft\Windows\Personalization' 'NoLockScreen' 1
    Set-RegistryValue 'HKLM:\SOFTWARE\Policies\Microsoft\Windows\System' 'DisableLockScreenAppNotifications' 1
    Invoke-PowerCfg @('/SETACVALUEINDEX', 'SCHEME_CURRENT', 'SUB_NONE', 'CONSOLELOCK', '0')

    # Screen saver: a blank or animated screen makes screenshots and clicks meaningless.
    Set-RegistryValue 'HKCU:\Control Panel\Desktop' 'ScreenSaveActive' '0' 'String'
    Set-RegistryValue 'HKCU:\Software\Policies\Microsoft\Windows\Control Panel\Desktop' 'ScreenSaveActive' '0' 'String'

    # Sleep, hibernation and monitor blanking.
    Invoke-PowerCfg @('/change', 'standby-timeout-ac', '0')
    Invoke-PowerCfg @('/change', 'monitor-timeout-ac', '0')
    Invoke-PowerCfg @('/change', 'hibernate-timeout-ac', '0')
    Invoke-PowerCfg @('/hibernate', 'off')

    # UAC: the consent prompt runs on the secure desktop, where input from the guest
    # (running as the user) does not land, so an elevation would hang the episode.
    # This VM is a disposable benchmark image, not a workstation.
    Set-RegistryValue 'HKLM:\SOFTWARE\Microsoft\Windows\CurrentVersion\Policies\System' 'PromptOnSecureDesktop' 0
    Set-RegistryValue 'HKLM:\SOFTWARE\Microsoft\Windows\CurrentVersion\Policies\System' 'ConsentPromptBehaviorAdmin' 0

    # First-run and "finish setting up" pop-ups that cover the window a task expects.
    Set-RegistryValue 'HKCU:\Software\Microsoft\Windows\CurrentVersion\UserProfileEngagement' 'ScoobeSystemSettingEnabled' 0
    Set-RegistryValue 'HKLM:\SOFTWARE\Policies\Microsoft\Windows\CloudContent' 'DisableWindowsConsumerFeatures' 1
    Set-RegistryValue 'HKLM:\SOFTWARE\Policies\Microsoft\Windows\CloudContent' 'DisableSoftLanding' 1
    Set-RegistryValue 'HKCU:\Software\Microsoft\Windows\CurrentVersion\ContentDeliveryManager' 'SubscribedContent-310093Enabled' 0
    Set-RegistryValue 'HKCU:\Software\Microsoft\Windows\CurrentVersion\ContentDeliveryManager' 'SubscribedContent-338389Enabled' 0
    Set-RegistryValue 'HKLM:\SOFTWARE\Policies\Microsoft\Edge' 'HideFirstRunExperience' 1
    Set-RegistryValue 'HKLM:\SOFTWARE\Policies\Microsoft\Edge' 'DefaultBrowserSettingEnabled' 0
    Set-RegistryValue 'HKLM:\SOFTWARE\Policies\Microsoft\Edge' 'StartupBoostEnabled' 0
    Set-RegistryValue 'HKLM:\SOFTWARE\Policies\Microsoft\EdgeUpdate' 'UpdateDefault' 0
    Set-RegistryValue 'HKLM:\SOFTWARE\Policies\Google\Chrome' 'DefaultBrowserSettingEnabled' 0
    Set-RegistryValue 'HKLM:\SOFTWARE\Policies\Google\Chrome' 'PromotionsEnabled' 0
    Set-RegistryValue 'HKLM:\SOFTWARE\Policies\Google\Chrome' 'BrowserSignin' 0
    Set-RegistryValue 'HKLM:\SOFTWARE\Policies\Google\Chrome' 'MetricsReportingEnabled' 0
    Set-RegistryValue 'HKLM:\SOFTWARE\Policies\Google\Chrome' 'PrivacySandboxPromptEnabled' 0
    # Chrome and Edge updaters would change the browser under a frozen image.
    Set-RegistryValue 'HKLM:\SOFTWARE\Policies\Google\Update' 'UpdateDefault' 0

    # Notifications: a toast takes focus from the window a task is typing into.
    Set-RegistryValue 'HKCU:\Software\Microsoft\Windows\CurrentVersion\PushNotifications' 'ToastEnabled' 0
    Set-RegistryValue 'HKCU:\Software\Policies\Microsoft\Windows\Explorer' 'DisableNotificationCenter' 1

    # File extensions: tasks name files with their extension and check Explorer's view.
    Set-RegistryValue 'HKCU:\Software\Microsoft\Windows\CurrentVersion\Explorer\Advanced' 'HideFileExt' 0

    # The screen at first logon as upstream's image shows it (the answer file's first
    # logon commands write the same; this is for images made another way): no "System
    # requirements not met" watermark on a VM Windows 11 calls unsupported, and no Task
    # View, Widgets, Chat or Copilot button on the taskbar.
    Set-RegistryValue 'HKCU:\Control Panel\UnsupportedHardwareNotificationCache' 'SV1' 0
    Set-RegistryValue 'HKCU:\Control Panel\UnsupportedHardwareNotificationCache' 'SV2' 0
    $advanced = 'HKCU:\Software\Microsoft\Windows\CurrentVersion\Explorer\Advanced'
    Set-RegistryValue $advanced 'ShowTaskViewButton' 0
    Set-RegistryValue $advanced 'TaskbarMn' 0
    Set-RegistryValue $advanced 'ShowCopilotButton' 0
    # Recent builds refuse a script's write of TaskbarDa (the User Choice Protection
    # driver); the documented widgets policy hides the button either way.
    Set-RegistryValue 'HKLM:\SOFTWARE\Policies\Microsoft\Dsh' 'AllowNewsAndInterests' 0
    try {
        Set-RegistryValue $advanced 'TaskbarDa' 0
    }
    catch {
        Write-Step "TaskbarDa not written ($($_.Exception.Message)); the widgets policy hides the button"
    }
    # The Store would update apps under a frozen image (2: automatic downloads off).
    Set-RegistryValue 'HKLM:\SOFTWARE\Policies\Microsoft\WindowsStore' 'AutoDownload' 2
    # OneDrive's per-user setup would start at every logon and put its window over the task's.
    $run = 'HKCU:\Software\Microsoft\Windows\CurrentVersion\Run'
    if ($null -ne (Get-ItemProperty -LiteralPath $run -Name 'OneDriveSetup' -ErrorAction SilentlyContinue)) {
        Remove-ItemProperty -LiteralPath $run -Name 'OneDriveSetup'
        Write-Step "removed $run\OneDriveSetup"
    }
}
catch {
    Write-Step "ERROR: $($_.Exception.Message)"
    exit 3
}
exit 0
