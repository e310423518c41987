#!/usr/bin/env python3
"""Writes the golden reject files of tests/golden: bad volumes and stores, each with the message
that isotope must give for it (NAME.expect, one line per command: "COMMAND: MESSAGE PART").
tests/cli/reject_test.cpp runs every command of every .expect file and checks exit 1, the message, and
that nothing was written. Run again after a change of the store format (docs/FORMAT.md):

    python3 tests/golden/make_rejects.py build/tools/isotope

The corrupted stores start from a 9^3 sphere converted with 8^3-node bricks (8 bricks in band 0).
Edits "under a valid checksum" recompute every checksum after the edit, as a careful forger would;
XXH64 is written out below (the format's checksum, seed 0) so that this needs only the standard
library."""
import gzip
import os
import struct
import subprocess
import sys
import tempfile

HERE = os.path.dirname(os.path.abspath(__file__))
M = 2**64 - 1
P1, P2, P3, P4, P5 = (0x9E3779B185EBCA87, 0xC2B2AE3D27D4EB4F, 0x165667B19E3779F9, 0x85EBCA77C2B2AE63,
                      0x27D4EB2F165667C5)


def rotl(x, r):
    return ((x << r) | (x >> (64 - r))) & M


def xxh64(data, seed=0):
    def rnd(acc, lane):
        return (rotl((acc + lane * P2) & M, 31) * P1) & M

    def merge(acc, v):
        return ((acc ^ rnd(0, v)) * P1 + P4) & M

    n, i = len(data), 0
    if n >= 32:
        v = [(seed + P1 + P2) & M, (seed + P2) & M, seed, (seed - P1) & M]
        while i + 32 <= n:
            for k in range(4):
                v[k] = rnd(v[k], struct.unpack_from('<Q', data, i + 8 * k)[0])
            i += 32
        h = (rotl(v[0], 1) + rotl(v[1], 7) + rotl(v[2], 12) + rotl(v[3], 18)) & M
        for k in range(4):
            h = merge(h, v[k])
    else:
        h = (seed + P5) & M
    h = (h + n) & M
    while i + 8 <= n:
        h = (rotl(h ^ rnd(0, struct.unpack_from('<Q', data, i)[0]), 27) * P1 + P4) & M
        i += 8
    if i + 4 <= n:
        h = (rotl(h ^ (struct.unpack_from('<I', data, i)[0] * P1 & M), 23) * P2 + P3) & M
        i += 4
    while i < n:
        h = (rotl(h ^ (data[i] * P5 & M), 11) * P1) & M
        i += 1
    h ^= h >> 33
    h = h * P2 & M
    h ^= h >> 29
    h = h * P3 & M
    return h ^ (h >> 32)


HEADER, BAND_TABLE, HEADER_SUM, ENTRY, SECTION_SUM = 1024, 256, 1016, 24, 8


def tiff(pages, rows_per_strip=None, photometric=None, description=None):
    """A little-endian TIFF of one-strip pages: (width, height, bits, sample_format, samples, data,
    strip_byte_count or None, strip_offset or None) each; what libtiff reads, written by hand.
    rows_per_strip (default: the height), photometric (3: a palette, with a colour map of zeros) and
    description (the first page's) make a page claim something else."""
    out = bytearray(b'II*\0' + bytes(4))
    link = 4  # where the next IFD's offset goes
    for n, (width, height, bits, fmt, samples, data, count, offset) in enumerate(pages):
        at = len(out)
        out += data
        extra = b''  # values too large for their entry, after the IFD
        tags = [(256, 4, 1, width), (257, 4, 1, height), (258, 3, 1, bits), (259, 3, 1, 1),
                (262, 3, 1, photometric if photometric is not None else 2 if samples == 3 else 1),
                (273, 4, 1, at if offset is None else offset), (277, 3, 1, samples),
                (278, 4, 1, rows_per_strip or height), (279, 4, 1, len(data) if count is None else count),
                (339, 3, 1, fmt)]
        if description and n == 0:
            tags.append((270, 2, len(description) + 1, description.encode() + b'\0'))
        if photometric == 3:
            tags.append((320, 3, 3 << bits, bytes(2 * (3 << bits))))
        tags.sort()
        if len(out) % 2:
            out += b'\0'
        struct.pack_into('<I', out, link, len(out))
        ifd_end = len(out) + 2 + 12 * len(tags) + 4
        out += struct.pack('<H', len(tags))
        for tag, kind, number, value in tags:
            if isinstance(value, bytes):
                out += struct.pack('<HHII', tag, kind, number, ifd_end + len(extra))
                extra += value + (b'\0' if len(value) % 2 else b'')
            else:
                out += struct.pack('<HHI', tag, kind, number) + (struct.pack('<HH', value, 0) if kind == 3 else
                                                                 struct.pack('<I', value))
        link = len(out)
        out += bytes(4) + extra
    return bytes(out)


def bands(b):
    out = []
    for j in range(20):
        off, size, _ = struct.unpack_from('<QQQ', b, BAND_TABLE + 24 * j)
        if size:
            out.append((j, off, size))
    return out


def reseal(b):
    """Every checksum recomputed: sections, band directories, header."""
    b = bytearray(b)
    for j, off, size in bands(b):
        if off + size > len(b):
            continue  # a directory outside the file: nothing to checksum
        for e in range(off, off + size, ENTRY):
            at = struct.unpack_from('<Q', b, e)[0]
            for s in struct.unpack_from('<4I', b, e + 8):
                if s > SECTION_SUM and at + s <= len(b):
                    struct.pack_into('<Q', b, at, xxh64(bytes(b[at + SECTION_SUM:at + s])))
                at += s
        struct.pack_into('<Q', b, BAND_TABLE + 24 * j + 16, xxh64(bytes(b[off:off + size])))
    struct.pack_into('<Q', b, HEADER_SUM, xxh64(bytes(b[:HEADER_SUM])))
    return bytes(b)


def edit(b, fmt, at, *values):
    b = bytearray(b)
    struct.pack_into(fmt, b, at, *values)
    return bytes(b)


def first_entry(b, band=0, index=0):
    _, off, _ = bands(b)[band]
    e = off + ENTRY * index
    return e, struct.unpack_from('<Q4I', b, e)


def main():
    isotope = sys.argv[1] if len(sys.argv) > 1 else os.path.join(HERE, '../../build/tools/isotope')
    with tempfile.TemporaryDirectory() as tmp:
        vol = os.path.join(tmp, 's_9x9x9_float32.raw')
        store = os.path.join(tmp, 's.isotope')
        subprocess.run([isotope, 'generate', 'sphere', '--size', '9', '-q', '-o', vol], check=True)
        subprocess.run([isotope, 'convert', vol, store, '--brick-bits', '3', '-q'], check=True)
        good = open(store, 'rb').read()
    assert reseal(good) == good, 'the XXH64 or the layout above does not match docs/FORMAT.md'

    cases = {}  # name -> (bytes, {command: message part})

    def store_case(name, data, message, verify=None):
        cases[name + '.isotope'] = (data, {'extract': message, 'verify': verify or message})

    nan, inf = float('nan'), float('inf')
    e0, (off0, *sizes0) = first_entry(good)
    store_case('truncated-header', good[:500], 'not an isotope store')
    # Named .isotope without the magic number: a damaged store, said so (not read as a raw volume).
    cases['zeros.isotope'] = (bytes(2048), {'extract': 'not an isotope store (wrong magic number)',
                                            'verify': 'wrong magic number'})
    store_case('version-3', reseal(edit(good, '<I', 8, 3)), 'convert the volume again')
    store_case('header-checksum', edit(good, '<d', 40, 2.0), 'header checksum mismatch')
    store_case('spacing-nan', reseal(edit(good, '<d', 48, nan)), 'spacing that is not a positive number')
    store_case('spacing-negative', reseal(edit(good, '<d', 40, -1.0)), 'spacing that is not a positive number')
    store_case('spacing-zero', reseal(edit(good, '<d', 56, 0.0)), 'spacing that is not a positive number')
    store_case('origin-infinite', reseal(edit(good, '<d', 64, -inf)), 'origin that is not finite')
    store_case('brick-bits-8', reseal(edit(good, '<B', 88, 8)), 'impossible brick size')
    store_case('dims-2-to-the-40', reseal(edit(good, '<q', 16, 2**40)), 'impossible dimensions')
    store_case('value-mapping-on-lossless', reseal(edit(good, '<d', 196, 2.0)), 'impossible value mapping')
    store_case('value-range-nan', reseal(edit(good, '<d', 108, nan)), 'impossible value range')
    store_case('value-range-beyond-float', reseal(edit(good, '<d', 116, 1e300)), 'impossible value range')
    store_case('reserved-byte', reseal(edit(good, '<B', 900, 1)), "reserved bytes are not zero")
    store_case('brick-count-lie', reseal(edit(good, '<q', 124, 9)), 'header contradicts itself')
    store_case('directory-past-the-end', reseal(edit(good, '<Q', BAND_TABLE, len(good) + 24)),
               'file is truncated or its directories overlap')
    store_case('directory-checksum', edit(good, '<I', e0 + 8, sizes0[0] + 1), 'directory checksum mismatch')
    store_case('entry-outside', reseal(edit(good, '<Q', e0, 2**63)), 'points outside the brick area')
    store_case('entry-wraps', reseal(edit(good, '<Q', e0, 2**64 - 16)), 'points outside the brick area')
    _, (off1, *sizes1) = first_entry(good, 0, 1)
    store_case('entries-overlap', reseal(edit(good, '<Q4I', e0 + ENTRY, off0, *sizes0)), 'overlaps entry')
    band0 = [first_entry(good, 0, i)[1] for i in range(8)]
    last = max(range(8), key=lambda i: band0[i][0])  # band 0's last brick in the file, moved 8 bytes on
    store_case('entries-gap', reseal(edit(good, '<Q', first_entry(good, 0, last)[0], band0[last][0] + 8)),
               'leaves a gap after entry')
    store_case('section-checksum', edit(good, '<B', off0 + SECTION_SUM + 20, good[off0 + SECTION_SUM + 20] ^ 0x40),
               'checksum mismatch')
    frame = bytearray(good)
    for i in range(off0 + SECTION_SUM, off0 + sizes0[0]):
        frame[i] = 0xA5
    store_case('section-not-zstd', reseal(bytes(frame)), 'impossible uncompressed size')
    store_case('trailing-bytes', good + b'\0' * 7, 'unexpected bytes after the directories')

    def volume_case(name, data, message):
        cases[name] = (data, {'extract': message})

    volume_case('short_4x4x4_uint8.raw', bytes(63), 'size 63 bytes, expected 64')
    volume_case('long_4x4x4_uint8.raw', bytes(65), 'size 65 bytes, expected 64')
    volume_case('nan_2x2x2_float32.raw', struct.pack('<8f', 0, 0, 0, nan, 0, 0, 0, 0), 'NaN')
    volume_case('infinite_2x2x2_float64.raw', struct.pack('<8d', 0, 0, 0, 0, 0, 0, inf, 0), 'infinite')
    volume_case('huge_4294967296x4294967296x4294967296_uint8.raw', bytes(8), 'too large')
    header = 'NRRD0004\ntype: uint8\ndimension: 3\nsizes: 3 3 3\nencoding: raw\n\n'
    volume_case('truncated.nrrd', header.encode() + bytes(20), 'data truncated')
    volume_case('dimension-4.nrrd', header.replace('dimension: 3', 'dimension: 4').encode() + bytes(27), 'dimension')
    volume_case('type-unknown.nrrd', header.replace('uint8', 'complex').encode() + bytes(27), 'type')
    volume_case('sizes-negative.nrrd', header.replace('3 3 3', '3 -3 3').encode() + bytes(27), 'sizes')
    volume_case('spacing-nan.nrrd', header.replace('encoding', 'spacings: 1 nan 1\nencoding').encode() + bytes(27),
                'spacings')
    volume_case('gzip-truncated.nrrd', header.replace('raw', 'gzip').encode() + gzip.compress(bytes(27))[:15], 'gzip')
    volume_case('gzip-bomb-header.nrrd', header.replace('raw', 'gzip').replace('3 3 3', '4096 4096 4096').encode()
                + gzip.compress(bytes(100)), 'too little gzip data')
    volume_case('data-file-missing.nhdr', header.replace('encoding', 'data file: missing.raw\nencoding').encode(),
                'no such file')
    volume_case('data-file-directory.nhdr', header.replace('encoding', 'data file: .\nencoding').encode(),
                'is a directory')
    volume_case('not-nrrd.nrrd', b'PK\x03\x04' + bytes(60), 'NRRD')
    # TIFF stacks (open_tiff_stack): each page is checked at open, before anything is read.
    gray = bytes(range(16))
    volume_case('tiff-rgb.tif', tiff([(4, 4, 8, 1, 3, bytes(48), None, None)] * 2), '3 samples per pixel')
    volume_case('tiff-int32.tif', tiff([(2, 2, 32, 2, 1, bytes(16), None, None)] * 2), '32-bit signed integer')
    volume_case('tiff-pages-differ.tif', tiff([(4, 4, 8, 1, 1, gray, None, None), (4, 3, 8, 1, 1, gray[:12], None, None)]),
                'page 1 is 4x3 uint8, where page 0 is 4x4 uint8')
    volume_case('tiff-lying-size.tif', tiff([(60000, 2, 8, 1, 1, gray, None, None)] * 2),
                'too few for 60000x2 uint8 values')
    volume_case('tiff-strip-beyond-end.tif', tiff([(4, 4, 8, 1, 1, gray, None, 1 << 20)] * 2),
                'its strips hold 0 bytes, too few for 4x4 uint8')
    volume_case('tiff-not-tiff.tif', b'II*\0' + bytes(4) + b'not a TIFF directory', 'not a readable TIFF file')
    # Pages that claim what their data is not: RowsPerStrip 3 of 4 rows wants 2 strips, the table
    # holds 1 (libtiff would read from offset 0, the header); a palette's indices; an ImageJ
    # hyperstack's interleaved channels; one page alone (no cells between slices).
    volume_case('tiff-rows-per-strip-lie.tif', tiff([(4, 4, 8, 1, 1, gray, None, None)] * 2, rows_per_strip=3),
                'does not describe its data consistently')
    volume_case('tiff-palette.tif', tiff([(4, 4, 8, 1, 1, gray, None, None)] * 2, photometric=3),
                'a palette (indexed colour) image')
    volume_case('tiff-hyperstack-channels.tif', tiff([(4, 4, 8, 1, 1, gray, None, None)] * 2,
                                                     description='ImageJ=1.54f\nimages=2\nchannels=2\nhyperstack=true\n'),
                'a hyperstack of 2 channels')
    volume_case('tiff-one-page.tif', tiff([(4, 4, 8, 1, 1, gray, None, None)]), 'volume dimensions 4x4x1')

    for f in os.listdir(HERE):
        if f not in ('make_rejects.py', 'README.md'):
            os.remove(os.path.join(HERE, f))
    for name, (data, expect) in sorted(cases.items()):
        with open(os.path.join(HERE, name), 'wb') as f:
            f.write(data)
        with open(os.path.join(HERE, name + '.expect'), 'w') as f:
            for command, message in expect.items():
                f.write(f'{command}: {message}\n')
    print(f'{len(cases)} reject files in {HERE}')


if __name__ == '__main__':
    main()
