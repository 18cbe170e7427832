<#
.SYNOPSIS
    A small window of our own for the live-desktop suite (tests/tests/live_desktop.rs).

.DESCRIPTION
    Windows Server runner images do not have the Windows 11 Calculator (calc.exe starts
    the classic win32calc there) and may lack other client apps, so the suite's
    Set-of-Marks and popup checks drive this WinForms window instead, which any Windows
    with Windows PowerShell 5.1 and the .NET Framework can show. Its controls have fixed
    accessible names: buttons Seven, Two, Plus and Equals, a label "Display is N" that
    shows the sum, an edit box named Notes, and a context menu (right click) with Copy,
    Paste and Select All. The window stays until it is closed.
#>
param(
    [string]$Title = 'Arena Testpad'
)
Set-StrictMode -Version Latest
$ErrorActionPreference = 'Stop'

Add-Type -AssemblyName System.Windows.Forms
Add-Type -AssemblyName System.Drawing
[System.Windows.Forms.Application]::EnableVisualStyles()

$form = New-Object System.Windows.Forms.Form
$form.Text = $Title
$form.ClientSize = New-Object System.Drawing.Size(380, 320)
$form.StartPosition = 'CenterScreen'

$display = New-Object System.Windows.Forms.Label
$display.Text = 'Display is 0'
$display.Location = New-Object System.Drawing.Point(20, 16)
$display.Size = New-Object System.Drawing.Size(340, 28)
$form.Controls.Add($display)

# The sum: the entry typed since the last operator, and what Plus kept.
$script:entry = 0
$script:kept = $null

function Add-CalcButton([string]$name, [int]$x, [int]$y, [scriptblock]$onClick) {
    $button = New-Object System.Windows.Forms.Button
    $button.Text = $name
    $button.Location = New-Object System.Drawing.Point($x, $y)
    $button.Size = New-Object System.Drawing.Size(80, 40)
    $button.Add_Click($onClick)
    $form.Controls.Add($button)
}

Add-CalcButton 'Seven' 20 56 { $script:entry = 7; $display.Text = 'Display is 7' }
Add-CalcButton 'Two' 110 56 { $script:entry = 2; $display.Text = 'Display is 2' }
Add-CalcButton 'Plus' 200 56 { $script:kept = $script:entry; $script:entry = 0 }
Add-CalcButton 'Equals' 290 56 {
    if ($null -ne $script:kept) {
        $script:entry = $script:kept + $script:entry
        $script:kept = $null
    }
    $display.Text = "Display is $($script:entry)"
}

$notes = New-Object System.Windows.Forms.TextBox
$notes.Name = 'Notes'
$notes.AccessibleName = 'Notes'
$notes.Multiline = $true
$notes.Location = New-Object System.Drawing.Point(20, 112)
$notes.Size = New-Object System.Drawing.Size(340, 120)
$form.Controls.Add($notes)

$menu = New-Object System.Windows.Forms.ContextMenuStrip
foreach ($item in 'Copy', 'Paste', 'Select All') {
    [void]$menu.Items.Add($item)
}
$form.ContextMenuStrip = $menu

[void]$form.ShowDialog()
