@echo off
rem Entry point of the arena's image preparation. dockur/windows copies the /oem
rem folder to C:\OEM and runs C:\OEM\install.bat at the end of the unattended
rem install; a custom answer file runs it from FirstLogonCommands
rem (unattend\autounattend-snippet.xml; `arena vm prepare` writes its own). It runs
rem setup.ps1 with the execution policy bypassed for this one process and records
rem its exit code in %ProgramData%\arena\logs\install.log: never in the OEM folder,
rem which may be read-only media.
setlocal
set "OEM=%~dp0"
rem %~dp0 ends with a backslash, which would escape the closing quote below.
set "OEM=%OEM:~0,-1%"
if not exist "%ProgramData%\arena\logs" mkdir "%ProgramData%\arena\logs"
set "LOG=%ProgramData%\arena\logs\install.log"
echo %DATE% %TIME% install.bat: running setup.ps1 from %OEM%>> "%LOG%"
powershell.exe -NoProfile -ExecutionPolicy Bypass -File "%OEM%\setup.ps1" -OemDir "%OEM%"
set "RC=%ERRORLEVEL%"
echo %DATE% %TIME% install.bat: setup.ps1 exited with %RC%>> "%LOG%"
exit /b %RC%
