@echo off
rem Entry point of the arena's image preparation. dockur/windows copies the /oem
rem folder to C:\OEM and runs C:\OEM\install.bat at the end of the unattended
rem install; a custom answer file runs it from FirstLogonCommands
rem (unattend\autounattend-snippet.xml). It runs setup.ps1 with the execution policy
rem bypassed for this one process and records its exit code in the log.
setlocal
set "OEM=%~dp0"
rem %~dp0 ends with a backslash, which would escape the closing quote below.
set "OEM=%OEM:~0,-1%"
set "LOG=%OEM%\arena-setup.log"
echo %DATE% %TIME% install.bat: running setup.ps1 from %OEM%>> "%LOG%"
powershell.exe -NoProfile -ExecutionPolicy Bypass -File "%OEM%\setup.ps1" -OemDir "%OEM%"
set "RC=%ERRORLEVEL%"
echo %DATE% %TIME% install.bat: setup.ps1 exited with %RC%>> "%LOG%"
exit /b %RC%
