/* What the C hosts (fmu_host.c, fmu_host3.c) need from the operating system: loading the FMU's
 * binary (dlopen on POSIX; LoadLibrary on Windows, behind the same names), an absolute path, and
 * the binaries/ folder and file extension of the platform the host was compiled for. With it the
 * hosts compile for Linux (x86_64, aarch64) and, cross-compiled (zig cc -target x86_64-windows-gnu),
 * for Windows, where they run the win64 / x86_64-windows binaries (tests/test_platforms.py, under
 * wine). */
#ifndef OVERCON_HOST_PLATFORM_H
#define OVERCON_HOST_PLATFORM_H

#include <limits.h>
#include <stdio.h>
#include <stdlib.h>

#if defined(_WIN32)
#include <windows.h>

#ifndef PATH_MAX
#define PATH_MAX 4096
#endif
#define RTLD_NOW 0
#define RTLD_LOCAL 0
#define HOST_FMI2_FOLDER "win64"
#define HOST_FMI3_OS "windows"
#define HOST_SUFFIX ".dll"
#define HOST_URI_PREFIX "file:///" /* + C:/dir: file:///C:/dir */

static void *dlopen(const char *path, int flags) {
    (void)flags;
    return (void *)LoadLibraryA(path);
}
static void *dlsym(void *lib, const char *name) { return (void *)GetProcAddress((HMODULE)lib, name); }
static int dlclose(void *lib) { return FreeLibrary((HMODULE)lib) ? 0 : -1; }
static const char *dlerror(void) {
    static char msg[64];
    snprintf(msg, sizeof msg, "Windows error %lu", (unsigned long)GetLastError());
    return msg;
}
/* The absolute path of an existing folder, with forward slashes (C:/dir). */
static char *realpath(const char *path, char *resolved) {
    if (!_fullpath(resolved, path, PATH_MAX) || GetFileAttributesA(resolved) == INVALID_FILE_ATTRIBUTES) return NULL;
    for (char *c = resolved; *c; c++)
        if (*c == '\\') *c = '/';
    return resolved;
}
#else
#include <dlfcn.h>

#define HOST_FMI2_FOLDER "linux64"
#define HOST_FMI3_OS "linux"
#define HOST_SUFFIX ".so"
#define HOST_URI_PREFIX "file://" /* + /dir: file:///dir */
#endif

#endif
