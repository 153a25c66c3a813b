/* Wine 8.0 lacks bcryptprimitives.dll!ProcessPrng, which Rust's std for windows-gnu
 * imports for its random numbers (HashMap seeds): without it every Rust .exe exits 53
 * before main. This shim forwards to BCryptGenRandom. Installed only into the test
 * Wine prefix by `cargo xtask setup`; it is never shipped. */
#include <windows.h>
#include <bcrypt.h>

BOOL WINAPI ProcessPrng(PBYTE data, SIZE_T len)
{
    while (len > 0) {
        ULONG chunk = len > 0x40000000 ? 0x40000000 : (ULONG)len;
        if (BCryptGenRandom(NULL, data, chunk, BCRYPT_USE_SYSTEM_PREFERRED_RNG) != 0)
            return FALSE;
        data += chunk;
        len -= chunk;
    }
    return TRUE;
}
