"""What a shared library shows a loader, read from its bytes: format, architecture, the symbols it
exports, the libraries it imports and (ELF) the glibc symbol versions it needs. For ELF (Linux),
PE (Windows DLL) and Mach-O (macOS), 64-bit little-endian, without any tool of the platform, so
the FMU binaries of every platform can be checked on any machine (:mod:`overcon.fmu.platforms`
checks each binary it compiles; the tests check the FMUs' binaries).

:func:`inspect` returns a :class:`BinaryFacts`; a file that is not such a library raises
:class:`BinaryFormatError` naming what is wrong.
"""
from __future__ import annotations

import dataclasses
import struct


class BinaryFormatError(ValueError):
    """Not a 64-bit little-endian ELF, PE or Mach-O shared library (or a truncated one)."""


@dataclasses.dataclass
class BinaryFacts:
    format: str                      # "elf", "pe", "macho"
    arch: str                        # "x86_64", "aarch64"
    exports: list[str]               # defined, exported symbol names (Mach-O: without the leading "_")
    imports: list[str]               # the libraries it needs (DT_NEEDED, import DLLs, LC_LOAD_DYLIB)
    versions: list[str] = dataclasses.field(default_factory=list)  # ELF: the symbol versions needed

    def glibc_max(self) -> tuple[int, ...]:
        """The newest GLIBC_x.y version needed (ELF), () when none."""
        found = [tuple(int(p) for p in v[6:].split(".")) for v in self.versions if v.startswith("GLIBC_2")]
        return max(found, default=())


def inspect(data: bytes) -> BinaryFacts:
    """The facts of a shared library's bytes (module docstring)."""
    if data[:4] == b"\x7fELF":
        return _elf(data)
    if data[:2] == b"MZ":
        return _pe(data)
    if data[:4] == b"\xcf\xfa\xed\xfe":
        return _macho(data)
    raise BinaryFormatError(f"not an ELF, PE or 64-bit Mach-O file (magic {data[:4].hex()})")


def _cstr(data: bytes, off: int) -> str:
    end = data.find(b"\0", off)
    if off < 0 or off >= len(data) or end < 0:
        raise BinaryFormatError(f"string offset {off} outside the file")
    return data[off:end].decode("utf-8", "replace")


def _unpack(fmt: str, data: bytes, off: int):
    try:
        return struct.unpack_from(fmt, data, off)
    except struct.error as exc:
        raise BinaryFormatError(f"truncated file: {fmt} at offset {off}") from exc


# ---------------------------------------------------------------------------------------------
# ELF

_ELF_MACHINES = {62: "x86_64", 183: "aarch64"}


def _elf(data: bytes) -> BinaryFacts:
    if data[4] != 2 or data[5] != 1:
        raise BinaryFormatError("ELF: not 64-bit little-endian")
    machine, = _unpack("<H", data, 18)
    shoff, = _unpack("<Q", data, 40)
    shentsize, shnum = _unpack("<HH", data, 58)
    sections = [_unpack("<IIQQQQIIQQ", data, shoff + k * shentsize) for k in range(shnum)]
    # (name, type, flags, addr, offset, size, link, info, addralign, entsize)
    exports, versions, needed = [], set(), []
    for sh in sections:
        if sh[1] == 11:  # SHT_DYNSYM
            strtab = sections[sh[6]][4]
            for k in range(1, sh[5] // 24):
                name, info, other, shndx = _unpack("<IBBH", data, sh[4] + 24 * k)
                bind, vis = info >> 4, other & 3
                if shndx != 0 and bind in (1, 2) and vis in (0, 3):  # defined GLOBAL/WEAK, DEFAULT/PROTECTED
                    exports.append(_cstr(data, strtab + name))
        elif sh[1] == 0x6FFFFFFE:  # SHT_GNU_verneed
            strtab, off = sections[sh[6]][4], sh[4]
            for _ in range(sh[7]):
                _, cnt, _, aux, nxt = _unpack("<HHIII", data, off)
                a = off + aux
                for _ in range(cnt):
                    _, _, _, vname, anext = _unpack("<IHHII", data, a)
                    versions.add(_cstr(data, strtab + vname))
                    a += anext
                off += nxt
        elif sh[1] == 6:  # SHT_DYNAMIC: DT_NEEDED entries
            strtab = sections[sh[6]][4]
            for k in range(sh[5] // 16):
                tag, val = _unpack("<qQ", data, sh[4] + 16 * k)
                if tag == 0:
                    break
                if tag == 1:
                    needed.append(_cstr(data, strtab + val))
    return BinaryFacts("elf", _ELF_MACHINES.get(machine, f"machine {machine}"), sorted(exports), needed,
                       sorted(versions))


# ---------------------------------------------------------------------------------------------
# PE

def _pe(data: bytes) -> BinaryFacts:
    pe, = _unpack("<I", data, 0x3C)
    if data[pe:pe + 4] != b"PE\0\0":
        raise BinaryFormatError("PE: no PE signature")
    machine, nsect, _, _, _, optsize, _ = _unpack("<HHIIIHH", data, pe + 4)
    opt = pe + 24
    if _unpack("<H", data, opt)[0] != 0x20B:
        raise BinaryFormatError("PE: not PE32+ (64-bit)")
    ndirs, = _unpack("<I", data, opt + 108)
    dirs = [_unpack("<II", data, opt + 112 + 8 * k) for k in range(min(ndirs, 16))]
    sects = [_unpack("<8sIIII", data, opt + optsize + 40 * k) for k in range(nsect)]

    def off(rva: int) -> int:
        for _, vsize, vaddr, rawsize, rawptr in sects:
            if vaddr <= rva < vaddr + max(vsize, rawsize):
                return rawptr + rva - vaddr
        raise BinaryFormatError(f"PE: RVA {rva:#x} in no section")

    exports, imports = [], []
    if dirs and dirs[0][0]:
        e = off(dirs[0][0])
        nnames, = _unpack("<I", data, e + 24)  # NumberOfNames; AddressOfNames at +32
        names_rva, = _unpack("<I", data, e + 32)
        for k in range(nnames):
            exports.append(_cstr(data, off(_unpack("<I", data, off(names_rva) + 4 * k)[0])))
    if len(dirs) > 1 and dirs[1][0]:
        i = off(dirs[1][0])
        while True:
            entry = _unpack("<IIIII", data, i)
            if not any(entry):
                break
            imports.append(_cstr(data, off(entry[3])))
            i += 20
    arch = {0x8664: "x86_64", 0xAA64: "aarch64"}.get(machine, f"machine {machine:#x}")
    return BinaryFacts("pe", arch, sorted(exports), imports)


# ---------------------------------------------------------------------------------------------
# Mach-O

def _macho(data: bytes) -> BinaryFacts:
    cputype, _, filetype, ncmds, _, _ = _unpack("<iiIIII", data, 4)
    if filetype != 6:
        raise BinaryFormatError(f"Mach-O: file type {filetype}, not a dylib (6)")
    off, imports, exports = 32, [], []
    symtab = dysymtab = None
    for _ in range(ncmds):
        cmd, size = _unpack("<II", data, off)
        if cmd in (0xC, 0x80000018, 0x1F):  # LC_LOAD_DYLIB, LC_LOAD_WEAK_DYLIB, LC_REEXPORT_DYLIB
            imports.append(_cstr(data, off + _unpack("<I", data, off + 8)[0]))
        elif cmd == 0x2:  # LC_SYMTAB
            symtab = _unpack("<IIII", data, off + 8)
        elif cmd == 0xB:  # LC_DYSYMTAB
            dysymtab = _unpack("<IIIIII", data, off + 8)
        off += size
    if symtab and dysymtab:
        symoff, _, stroff, _ = symtab
        iext, next_ = dysymtab[2], dysymtab[3]
        for k in range(iext, iext + next_):
            strx, ntype = _unpack("<IB", data, symoff + 16 * k)
            if ntype & 0x01 and not ntype & 0x10:  # N_EXT, not N_PEXT
                name = _cstr(data, stroff + strx)
                exports.append(name[1:] if name.startswith("_") else name)
    arch = {0x01000007: "x86_64", 0x0100000C: "aarch64"}.get(cputype, f"cputype {cputype:#x}")
    return BinaryFacts("macho", arch, sorted(exports), imports)
