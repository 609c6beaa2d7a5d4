/* The libm functions whose glibc symbol got a new version after glibc 2.17 (exp, pow: GLIBC_2.29,
 * hypot: GLIBC_2.35, on x86_64), bound to their first version when OVK_GLIBC_PINS is defined (the
 * FMU binaries: overcon.fmu.platforms.FMU_FLAGS), so a library compiled on a new glibc still loads
 * on glibc 2.17 (RHEL 7 and later, Ubuntu 14.04 and later). Off by default: a pinned reference
 * needs libm on the link line, which a tool compiling the FMU's sources may not give. The old and the new
 * version of each compute the same number on the same glibc: they differ only in how an overflow
 * or a domain error is reported (errno, the retired SVID matherr), which the core never reads.
 * Included by core.h, so by every file of the core and of the FMI layer; nothing on other C
 * libraries (musl, macOS, Windows), where the plain names are the only ones. */
#ifndef OVERCON_LIBM_PINS_H
#define OVERCON_LIBM_PINS_H

#include <limits.h> /* defines __GLIBC__ on glibc (through features.h) */

#if defined(__GLIBC__) && defined(__GNUC__) && defined(OVK_GLIBC_PINS)
#if defined(__x86_64__) && !defined(__ILP32__)
__asm__(".symver exp,exp@GLIBC_2.2.5");
__asm__(".symver pow,pow@GLIBC_2.2.5");
__asm__(".symver hypot,hypot@GLIBC_2.2.5");
#elif defined(__aarch64__)
__asm__(".symver exp,exp@GLIBC_2.17");
__asm__(".symver pow,pow@GLIBC_2.17");
__asm__(".symver hypot,hypot@GLIBC_2.17");
#endif
#endif

#endif
