/*
 * A stand-in for bcryptprimitives.dll, for running Rust programs under Wine 8.
 *
 * Rust 1.78 and later get their random bytes from ProcessPrng, which Windows 10+
 * exports from bcryptprimitives.dll and Wine 8 does not. This DLL exports that one
 * function, answered by BCryptGenRandom with the system-preferred generator, which
 * Wine does implement. It is only for the Wine test prefix: real Windows has the
 * genuine DLL, and this file is never shipped.
 *
 * Build: x86_64-w64-mingw32-gcc -shared -O2 -o bcryptprimitives.dll \
 *        bcryptprimitives.c bcryptprimitives.def -lbcrypt
 */
#include <windows.h>
#include <bcrypt.h>

BOOL WINAPI ProcessPrng(PBYTE data, SIZE_T len)
{
    /* BCryptGenRandom takes a ULONG length, so large requests go in pieces. */
    while (len > 0) {
        ULONG chunk = len > 0x10000000 ? 0x10000000 : (ULONG)len;
        if (!BCRYPT_SUCCESS(BCryptGenRandom(NULL, data, chunk, BCRYPT_USE_SYSTEM_PREFERRED_RNG)))
            return FALSE;
        data += chunk;
        len -= chunk;
    }
    return TRUE;
}
