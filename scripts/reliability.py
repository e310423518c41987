#!/usr/bin/env python3
"""Tries isotope as a hostile user would and writes the table of docs/RELIABILITY.md: bad paths,
bad volumes, corrupted stores by kind (the golden reject files of tests/golden and random
corruptions), bad numbers on the command line, HTTP abuse of `isotope serve`, and the fuzz runs of
scripts/fuzz.sh. Every row must hold: a clear message and exit 1 (2 for usage), or the HTTP status
the docs promise; nothing written; no crash (no signal); no hang (each command within 30 s); memory
bounded (peak RSS of every command below 1 GB, the server's growth under a crowd below 400 MB).
Exits 1 when a row does not hold. Run by scripts/reliability.sh (which builds and fuzzes first):

    python3 scripts/reliability.py --isotope build/tools/isotope [--fuzz-stats FILE] [--out FILE]
"""
import argparse
import json
import os
import random
import re
import resource
import shutil
import signal
import socket
import stat
import subprocess
import sys
import tempfile
import threading
import time
import urllib.parse

ROOT = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))
REJECT = os.path.join(ROOT, 'tests', 'golden')
TIMEOUT = 30
RSS_LIMIT_MB = 1024


class Row:
    def __init__(self, category, case, tried=1):
        self.category, self.case, self.tried = category, case, tried
        self.got, self.message, self.problems = '', '', []
        self.max_rss_mb, self.max_seconds = 0.0, 0.0

    def ok(self):
        return not self.problems


rows = []


def run(argv, cwd=None, limit_fsize=None):
    """Runs argv; returns (exit code, -signal or 'hang', its stdout+stderr, seconds, its own peak RSS in MB)."""
    def pre():
        if limit_fsize is not None:
            resource.setrlimit(resource.RLIMIT_FSIZE, (limit_fsize, limit_fsize))
    start = time.monotonic()
    with tempfile.TemporaryFile() as log:
        p = subprocess.Popen(argv, cwd=cwd, stdout=log, stderr=subprocess.STDOUT, preexec_fn=pre)
        while True:  # os.wait4: this child's own rusage, not the largest of all children so far
            pid, status, usage = os.wait4(p.pid, os.WNOHANG)
            if pid:
                break
            if time.monotonic() - start > TIMEOUT:
                p.kill()
                os.wait4(p.pid, 0)
                p.returncode = 0
                return 'hang', '', TIMEOUT, 0.0
            time.sleep(0.002)
        p.returncode = 0  # reaped above; keeps Popen from waiting again
        log.seek(0)
        out = log.read().decode(errors='replace')
    rc = os.waitstatus_to_exitcode(status)
    return rc, out, time.monotonic() - start, usage.ru_maxrss / 1024


def listing(d):
    out = set()
    for base, dirs, files in os.walk(d):
        for n in dirs + files:
            out.add(os.path.relpath(os.path.join(base, n), d))
    return out


def expect_refusal(row, argv, cwd, code=1, message=None, unchanged=(), limit_fsize=None):
    before = listing(cwd)
    contents = {p: open(p, 'rb').read() for p in unchanged if os.path.isfile(p)}
    rc, out, secs, rss = run(argv, cwd=cwd, limit_fsize=limit_fsize)
    row.max_rss_mb, row.max_seconds = max(row.max_rss_mb, rss), max(row.max_seconds, secs)
    lines = out.strip().splitlines()
    # isotope's own first line; under mpirun the launcher's banner may come before it.
    first = next((l for l in lines if l.startswith('isotope:')), lines[0] if lines else '')
    row.got = f'exit {rc}' if isinstance(rc, int) and rc >= 0 else ('hang' if rc == 'hang' else f'signal {-rc}')
    row.message = row.message or first
    if rc != code:
        row.problems.append(f'{" ".join(argv[1:3])}: exit {rc}, expected {code}: {first}')
    if code == 1 and not first.startswith('isotope: error: '):
        row.problems.append(f'no "isotope: error:" message: {first!r}')
    if message and message not in out:
        row.problems.append(f'message lacks {message!r}: {first!r}')
    if listing(cwd) != before:
        row.problems.append(f'wrote {sorted(listing(cwd) - before)} / removed {sorted(before - listing(cwd))}')
    for p, b in contents.items():
        if open(p, 'rb').read() != b:
            row.problems.append(f'{p} changed')
    if rss > RSS_LIMIT_MB:
        row.problems.append(f'peak RSS {rss:.0f} MB')


def add(row):
    rows.append(row)
    return row


def bad_paths(iso, work):
    vol = os.path.join(work, 's_33x33x33_float32.raw')
    subprocess.run([iso, 'generate', 'sphere', '--size', '33', '-q', '-o', vol], check=True)
    d = os.path.join(work, 'paths')
    os.makedirs(d)
    shutil.copy(vol, d)
    v = os.path.join(d, os.path.basename(vol))
    ex = [iso, 'extract', v, '--iso', '0']

    expect_refusal(add(Row('Bad paths', '`-o` into a folder that does not exist')), ex + ['-o', f'{d}/no/m.ply'], d,
                   message='does not exist')
    fifo = os.path.join(d, 'pipe.ply')
    os.mkfifo(fifo)
    expect_refusal(add(Row('Bad paths', '`-o` names a FIFO (stays a FIFO)')), ex + ['-o', fifo], d, message='is a FIFO')
    r = add(Row('Bad paths', '`-o` names a character device made by mknod (stays a device)'))
    dev = os.path.join(d, 'null.ply')
    try:
        os.mknod(dev, 0o666 | stat.S_IFCHR, os.makedev(1, 3))
        expect_refusal(r, ex + ['-o', dev], d, message='device')
        if not stat.S_ISCHR(os.stat(dev).st_mode):
            r.problems.append('the device was replaced')
        os.remove(dev)
    except PermissionError:
        r.got, r.message = 'not run', 'mknod needs root'
    os.remove(fifo)
    expect_refusal(add(Row('Bad paths', '`-o` names no mesh format (the input `.raw`)')), ex + ['-o', v], d, code=2,
                   message="unknown mesh format '.raw'", unchanged=[v])
    os.symlink(v, os.path.join(d, 'same.ply'))
    expect_refusal(add(Row('Bad paths', '`-o` is the input (a link named `.ply`)')), ex + ['-o', f'{d}/same.ply'], d,
                   message='is the same file as INPUT', unchanged=[v])
    os.remove(os.path.join(d, 'same.ply'))
    os.symlink(v, os.path.join(d, 'link.raw'))
    expect_refusal(add(Row('Bad paths', '`convert X LINK-TO-X`')), [iso, 'convert', v, os.path.join(d, 'link.raw')], d,
                   message='is the same file as INPUT', unchanged=[v])
    os.remove(os.path.join(d, 'link.raw'))
    expect_refusal(add(Row('Bad paths', '`--report` is the same file as `-o`')),
                   ex + ['-o', f'{d}/m.ply', '--report', f'{d}/m.ply'], d, message='is the same file as -o')
    old = os.path.join(d, 'old.ply')
    open(old, 'w').write('old')
    expect_refusal(add(Row('Bad paths', 'full disk while writing (file size limit 16 KiB; old output kept)')),
                   ex + ['-o', old], d, message='File too large', unchanged=[old], limit_fsize=16 << 10)
    os.remove(old)
    os.makedirs(os.path.join(d, 'loop'))
    os.symlink('b.ply', os.path.join(d, 'loop', 'a.ply'))
    os.symlink('a.ply', os.path.join(d, 'loop', 'b.ply'))
    expect_refusal(add(Row('Bad paths', '`-o` is a symbolic link loop')), ex + ['-o', f'{d}/loop/a.ply'], d)
    shutil.rmtree(os.path.join(d, 'loop'))
    r = add(Row('Bad paths', '`-o` is a symbolic link to a file: the file is replaced, the link stays'))
    target = os.path.join(d, 'target.ply')
    open(target, 'w').write('old')
    os.symlink(target, os.path.join(d, 'link.ply'))
    rc, out, secs, rss = run(ex + ['-q', '-o', os.path.join(d, 'link.ply')])
    r.got, r.message, r.max_seconds, r.max_rss_mb = f'exit {rc}', 'written through the link', secs, rss
    if rc != 0 or not os.path.islink(os.path.join(d, 'link.ply')) or open(target, 'rb').read(3) != b'ply':
        r.problems.append(f'exit {rc}, link or target wrong: {out[:200]}')
    os.remove(os.path.join(d, 'link.ply'))
    os.remove(target)
    # --parts DIR writes a folder (docs/RELIABILITY.md, "Outputs"): never over one that holds the input or
    # files isotope did not write, which it deleted before, exit 0.
    p = os.path.join(d, 'p')
    os.makedirs(os.path.join(p, 'sub'))
    shutil.copy(v, p)
    open(os.path.join(p, 'sub', 'notes.txt'), 'w').write('x\n')
    expect_refusal(add(Row('Bad paths', '`--parts DIR` where DIR holds the input and a folder of notes')),
                   [iso, 'extract', os.path.join(p, os.path.basename(v)), '--iso', '0', '--eps', '0.01', '--parts', p],
                   d, message='holds INPUT', unchanged=[os.path.join(p, os.path.basename(v)),
                                                       os.path.join(p, 'sub', 'notes.txt')])
    expect_refusal(add(Row('Bad paths', '`--parts DIR` where DIR holds files isotope did not write')),
                   ex + ['--eps', '0.01', '--parts', p], d, message='is a folder that isotope did not write',
                   unchanged=[os.path.join(p, 'sub', 'notes.txt')])
    shutil.rmtree(p)
    # A slice folder with a link that leads nowhere between its slices: named, whatever the order.
    sl = os.path.join(d, 'slices')
    os.makedirs(sl)
    subprocess.run([iso, 'generate', 'sphere', '--size', '9', '-q', '-o', os.path.join(sl, 'v_9x9x9_float32.raw')],
                   check=True)
    raw9 = open(os.path.join(sl, 'v_9x9x9_float32.raw'), 'rb').read()
    os.remove(os.path.join(sl, 'v_9x9x9_float32.raw'))
    for z in (1, 3):  # single-page float32 TIFFs of one 9x9 slice each, written by hand
        open(os.path.join(sl, f's{z}.tif'), 'wb').write(one_page_tiff(9, 9, raw9[:324]))
    os.symlink('gone.tif', os.path.join(sl, 's2.tif'))
    expect_refusal(add(Row('Bad paths', 'a slice folder with a `.tif` link that leads nowhere')),
                   [iso, 'extract', sl, '--iso', '0', '-o', f'{d}/m.ply'], d,
                   message='s2.tif: a symbolic link that leads nowhere')
    shutil.rmtree(sl)
    # Inputs that are not regular files would block a reader forever (a FIFO) or never end.
    inputs = [('a FIFO', 'in_2x2x2_uint8.raw', lambda p: os.mkfifo(p), 'is a FIFO'),
              ('a directory', 'dir_2x2x2_uint8.raw', lambda p: os.makedirs(p), 'is a directory'),
              ('a file that does not exist', 'none_2x2x2_uint8.raw', lambda p: None, 'no such file'),
              ('a FIFO named .isotope', 'in.isotope', lambda p: os.mkfifo(p), 'is a FIFO'),
              ('a FIFO named .nrrd', 'in.nrrd', lambda p: os.mkfifo(p), 'is a FIFO')]
    for what, name, make, message in inputs:
        p = os.path.join(d, name)
        make(p)
        r = add(Row('Bad paths', f'input is {what}', tried=2))
        expect_refusal(r, [iso, 'extract', p, '--iso', '0', '-o', f'{d}/m.ply'], d, message=message)
        expect_refusal(r, [iso, 'convert', p, f'{d}/s.isotope'], d, message=message)
        if os.path.isdir(p):
            os.rmdir(p)
        elif os.path.exists(p):
            os.remove(p)
    return v


def one_page_tiff(width, height, data):
    """A little-endian single-page float32 TIFF of one strip."""
    import struct
    tags = [(256, 4, width), (257, 4, height), (258, 3, 32), (259, 3, 1), (262, 3, 1), (273, 4, 8), (277, 3, 1),
            (278, 4, height), (279, 4, len(data)), (339, 3, 3)]
    out = b'II*\0' + struct.pack('<I', 8 + len(data)) + data + struct.pack('<H', len(tags))
    for tag, kind, value in tags:
        out += struct.pack('<HHI', tag, kind, 1) + (struct.pack('<HH', value, 0) if kind == 3 else
                                                   struct.pack('<I', value))
    return out + bytes(4)


def reject_files(iso, work):
    d = os.path.join(work, 'reject')
    os.makedirs(d)
    kinds = {}
    for name in sorted(os.listdir(REJECT)):
        if not name.endswith('.expect'):
            continue
        f = name[:-len('.expect')]
        shutil.copy(os.path.join(REJECT, f), d)
        p = os.path.join(d, f)
        category = 'Corrupted stores' if f.endswith('.isotope') else 'Bad volumes'
        r = add(Row(category, f'`tests/golden/{f}`'))
        for line in open(os.path.join(REJECT, name)):
            command, message = line.rstrip('\n').split(': ', 1)
            argv = [iso, command, p] + (['--iso', '0.5', '-o', f'{d}/out.ply'] if command == 'extract' else [])
            r.tried = len(open(os.path.join(REJECT, name)).read().splitlines())
            expect_refusal(r, argv, d, message=message, unchanged=[p])
        r.message = r.message.replace(d + '/', '')
        kinds[f] = r
    return kinds


def random_corruptions(iso, work, volume, count):
    d = os.path.join(work, 'random')
    os.makedirs(d)
    store = os.path.join(work, 'good.isotope')
    subprocess.run([iso, 'convert', volume, store, '--brick-bits', '3', '-q'], check=True)
    good = open(store, 'rb').read()
    rng = random.Random(18)
    kinds = {'byte flipped': [], 'truncated': [], 'bytes inserted': [], 'run of bytes overwritten': []}
    for i in range(count):
        b = bytearray(good)
        kind = list(kinds)[i % 4]
        at = rng.randrange(len(b))
        if kind == 'byte flipped':
            b[at] ^= 1 << rng.randrange(8)
        elif kind == 'truncated':
            b = b[:at]
        elif kind == 'bytes inserted':
            b[at:at] = bytes(rng.randrange(256) for _ in range(rng.randrange(1, 64)))
        else:
            n = rng.randrange(1, 200)
            b[at:at + n] = bytes(rng.randrange(256) for _ in range(min(n, len(b) - at)))
        kinds[kind].append(bytes(b))
    # The extraction reads only the bricks (and sections) it needs: a corruption elsewhere cannot
    # change its mesh, which is then byte for byte the good store's. verify reads everything.
    reference = os.path.join(work, 'reference.ply')
    subprocess.run([iso, 'extract', store, '--iso', '0', '-q', '-o', reference], check=True)
    reference_bytes = open(reference, 'rb').read()
    for kind, stores in kinds.items():
        r = add(Row('Corrupted stores', f'random: {kind} (a 33^3 store, 8^3 bricks), `extract` and `verify` each',
                    tried=2 * len(stores)))
        p = os.path.join(d, 'bad.isotope')
        mesh = os.path.join(d, 'm.ply')
        refused = unread = 0
        for b in stores:
            open(p, 'wb').write(b)
            rc, out, secs, rss = run([iso, 'extract', p, '--iso', '0', '-q', '-o', mesh], cwd=d)
            r.max_rss_mb, r.max_seconds = max(r.max_rss_mb, rss), max(r.max_seconds, secs)
            if rc == 0 and open(mesh, 'rb').read() == reference_bytes:
                unread += 1
            elif rc == 1 and out.startswith('isotope: error: ') and not os.path.exists(mesh):
                refused += 1
            else:
                r.problems.append(f'extract: exit {rc}, {"a different mesh" if rc == 0 else out[:100]}')
            if os.path.exists(mesh):
                os.remove(mesh)
            expect_refusal(r, [iso, 'verify', p], d, unchanged=[p])
        r.got = f'extract: exit 1 x{refused}, same mesh x{unread}; verify: exit 1'
        r.message = r.message.replace(d + '/', '')
        os.remove(p)
    return store


def cli_numbers(iso, work, volume):
    cases = [('--threads -1', ['extract', volume, '--iso', '0', '--threads', '-1', '-o', 'm.ply'], '--threads'),
             ('--threads 100000', ['extract', volume, '--iso', '0', '--threads', '100000', '-o', 'm.ply'], '--threads'),
             ('--iso nan', ['extract', volume, '--iso', 'nan', '-o', 'm.ply'], '--iso'),
             ('--eps -1', ['extract', volume, '--iso', '0', '--eps', '-1', '-o', 'm.ply'], '--eps'),
             ('--compare-voxels 1e-300', ['extract', volume, '--iso', '0', '--compare-full', '--compare-voxels',
                                          '1e-300', '-o', 'm.ply', '--report', 'r.json'], '--compare-voxels'),
             ('--max-triangles -5', ['extract', volume, '--iso', '0', '--max-triangles', '-5', '-o', 'm.ply'],
              '--max-triangles'),
             ('--max-triangles 0', ['extract', volume, '--iso', '0', '--max-triangles', '0', '-o', 'm.ply'],
              '--max-triangles'),
             ('--max-triangles 1000 --eps 0.1', ['extract', volume, '--iso', '0', '--max-triangles', '1000', '--eps',
                                                 '0.1', '-o', 'm.ply'], 'give eps or max-triangles, not both'),
             ('--cache-mb 0', ['extract', volume, '--iso', '0', '--cache-mb', '0', '-o', 'm.ply'], '--cache-mb'),
             ('--dims 0x4x4', ['extract', volume, '--dims', '0x4x4', '--type', 'uint8', '--iso', '0', '-o', 'm.ply'],
              '--dims'),
             ('--focus 1,2 --radius 1', ['extract', volume, '--iso', '0', '--focus', '1,2', '--radius', '1', '-o',
                                         'm.ply'], '--focus'),
             ('--focus 1,2,3 --radius -1', ['extract', volume, '--iso', '0', '--focus', '1,2,3', '--radius', '-1',
                                            '-o', 'm.ply'], '--radius'),
             ('--port 70000', ['serve', volume, '--port', '70000'], '--port'),
             ('--zstd-level 30', ['convert', volume, 's.isotope', '--zstd-level', '30'], '--zstd-level')]
    d = os.path.join(work, 'cli')
    os.makedirs(d)
    for what, args, named in cases:
        r = add(Row('Command line', f'`{what}`'))
        expect_refusal(r, [iso] + args, d, code=2, message=named)


KILL_RANK_1 = """#!/bin/sh
if [ "$OMPI_COMM_WORLD_RANK" = 1 ]; then exec timeout -s KILL 0.5 "$@"; fi
exec "$@"
"""


def distributed(iso, work):
    """`mpirun -n 2 isotope ...` (docs/DISTRIBUTED.md): a rank that fails stops both with its message, a
    rank that is killed ends the job, and neither leaves a file behind."""
    os.environ.update(OMPI_ALLOW_RUN_AS_ROOT='1', OMPI_ALLOW_RUN_AS_ROOT_CONFIRM='1')
    mpirun = ['mpirun', '--oversubscribe', '-n', '2']
    d = os.path.join(work, 'mpi')
    os.makedirs(d)
    embryo = os.path.join(ROOT, '..', 'shared', 'data', 'embryo_256x256x256_uint8.raw')
    store = os.path.join(d, 'embryo.isotope')
    subprocess.run([iso, 'convert', embryo, store, '--quiet'], check=True)
    band0 = json.loads(subprocess.run([iso, 'info', store, '--json'], check=True, capture_output=True,
                                      text=True).stdout)['band_detail'][0]['bytes']
    data = bytearray(open(store, 'rb').read())
    for at in range(1024 + int(0.98 * band0), 1024 + band0, 4096):  # bricks only the last of 2 ranks reads
        data[at] ^= 0xFF
    open(store, 'wb').write(bytes(data))
    r = add(Row('Across ranks', '`mpirun -n 2 isotope extract`: bricks only rank 1 reads are corrupt'))
    expect_refusal(r, mpirun + [iso, 'extract', 'embryo.isotope', '--iso', '50', '--eps', '4', '--threads', '1',
                                '-o', 'm.ply'], d, code=1, message='rank 1 of 2: ')
    wrapper = os.path.join(work, 'kill1.sh')
    open(wrapper, 'w').write(KILL_RANK_1)
    os.chmod(wrapper, 0o755)
    raw = os.path.join(d, 'noise_321x321x321_float32.raw')
    subprocess.run([iso, 'generate', 'noise', '--size', '321', '-q', '-o', raw], check=True)
    r = add(Row('Across ranks', '`mpirun -n 2 isotope convert`: rank 1 killed (SIGKILL) half a second in'))
    r.message = "mpirun noticed that process rank 1 ... exited on signal 9 (Killed)"  # its banner's first line is dashes
    expect_refusal(r, mpirun + [wrapper, iso, 'convert', os.path.basename(raw), 's.isotope', '--threads', '1',
                                '--memory-mb', '16'], d, code=137, message='exited on signal 9')
    r = add(Row('Across ranks', '`--parts DIR` and `-o` both given'))
    expect_refusal(r, mpirun + [iso, 'extract', 'embryo.isotope', '--iso', '50', '--parts', 'p', '-o', 'm.ply'], d,
                   code=2, message='--parts')
    # MPMD: two ranks run one command, a third another; every rank compares its words first.
    same = [iso, 'extract', 'embryo.isotope', '--iso', '50', '--eps', '8', '-o', 'm.ply']
    for what, third in (('`--eps -1`', same[:6] + ['-1', '-o', 'm.ply']),
                        ('`isotope info`', [iso, 'info', 'embryo.isotope']),
                        ('another `--iso`', same[:3] + ['--iso', '60'] + same[5:])):
        r = add(Row('Across ranks', f'MPMD: two ranks extract, a third runs {what}'))
        expect_refusal(r, ['mpirun', '--oversubscribe', '-n', '2'] + same + [':', '-n', '1'] + third, d, code=2,
                       message='the ranks of this job run different commands')
    without = os.path.join(os.path.dirname(os.path.dirname(iso)), 'tests', 'isotope_without_mpi')
    r = add(Row('Across ranks', '`mpirun -n 3` of an isotope built without MPI'))
    if os.path.exists(without):
        expect_refusal(r, ['mpirun', '--oversubscribe', '-n', '3', without] + same[1:], d, code=1,
                       message='built without MPI')
    else:
        r.got, r.message = 'not run', f'{without} not built'
        r.problems.append('not run')


def http(port, raw, timeout=10):
    s = socket.create_connection(('127.0.0.1', port), timeout=timeout)
    s.sendall(raw)
    data = b''
    try:
        while True:
            chunk = s.recv(65536)
            if not chunk:
                break
            data += chunk
            if b'\r\n\r\n' in data:
                head, _, body = data.partition(b'\r\n\r\n')
                length = [l for l in head.split(b'\r\n') if l.lower().startswith(b'content-length:')]
                if length and len(body) >= int(length[0].split(b':')[1]):
                    break
    finally:
        s.close()
    head = data.split(b'\r\n\r\n')[0].decode(errors='replace')
    status = int(head.split(' ')[1]) if head.startswith('HTTP/') else None
    return status, head, data


def vm_kb(pid, field):
    for line in open(f'/proc/{pid}/status'):
        if line.startswith(field + ':'):
            return int(line.split()[1])
    return 0


def http_abuse(iso, work, store):
    p = subprocess.Popen([iso, 'serve', store, '--port', '0', '-q'], stdout=subprocess.PIPE, stderr=subprocess.STDOUT)
    line = p.stdout.readline().decode()
    port = int(line.rsplit(':', 1)[1].strip().strip('/'))
    get = lambda target, extra=b'': http(port, b'GET ' + target.encode() + b' HTTP/1.1\r\nHost: x\r\n' + extra +
                                         b'Connection: close\r\n\r\n')

    def row(case, status, expected, message='', tried=1):
        r = add(Row('HTTP abuse (`isotope serve`)', case, tried))
        r.got, r.message = (f'HTTP {status}' if isinstance(status, int) else str(status)), message
        if status not in expected:
            r.problems.append(f'HTTP {status}, expected {expected}')
        return r

    status, head, _ = http(port, b'OPTIONS /api/info HTTP/1.1\r\nHost: x\r\nConnection: close\r\n\r\n')
    r = row('OPTIONS', status, {405}, 'Allow: GET, HEAD')
    if 'Allow: GET, HEAD' not in head:
        r.problems.append('no Allow header')
    status, _, _ = http(port, b'POST /api/extract HTTP/1.1\r\nHost: x\r\nContent-Length: 0\r\nConnection: close\r\n\r\n')
    row('POST without a body', status, {405})
    status, _, _ = http(port, b'POST /api/extract HTTP/1.1\r\nHost: x\r\nContent-Length: 100000\r\nConnection: close'
                              b'\r\n\r\n' + b'x' * 100000)
    row('POST with a 100 KB body', status, {405, 413})
    status, _, _ = get('/api/info?' + 'a' * 20000)
    row('URL of 20 KB', status, {414, 400})
    status, _, _ = get('/api/info', b'X-Big: ' + b'b' * 20000 + b'\r\n')
    row('header of 20 KB', status, {400, 431})
    status, _, _ = http(port, b'GARBAGE\r\n\r\n')
    row('request line that is not HTTP', status if status else 'closed', {400, 'closed'}, 'closed or 400')
    bad = ['/api/extract', '/api/extract?iso=nan', '/api/extract?iso=0&eps=-1', '/api/extract?iso=0&iso=1',
           '/api/extract?iso=0&topology=magic', '/api/extract?iso=0&bogus=1', '/api/extract?iso=1e999']
    statuses = {get(u)[0] for u in bad}
    row('bad extraction parameters (missing, NaN, negative, repeated, unknown, out of range)',
        statuses.pop() if len(statuses) == 1 else statuses, {400}, 'a 400 that names the parameter', len(bad))
    paths = ['/../../etc/passwd', '/%2e%2e/%2e%2e/etc/passwd', '/..%2f..%2fetc%2fpasswd', '//etc/passwd',
             '/index.html/../../../etc/passwd']
    statuses = {get(urllib.parse.quote(u, safe='/%.'))[0] for u in paths}
    row('paths outside the viewer (.., encoded ..)', statuses.pop() if len(statuses) == 1 else statuses, {404, 400},
        'no file outside the viewer', len(paths))
    # 50 connections dripping a request byte by byte; a normal request meanwhile.
    drips = []
    for _ in range(50):
        s = socket.create_connection(('127.0.0.1', port))
        s.sendall(b'GET /api/in')
        drips.append(s)
    time.sleep(0.2)
    start = time.monotonic()
    status, _, _ = get('/api/info')
    seconds = time.monotonic() - start
    r = row('50 slow-drip connections open, then a normal request', status, {200}, f'answered in {1e3 * seconds:.0f} ms')
    if seconds > 1:
        r.problems.append(f'{seconds:.2f} s')
    for s in drips:
        s.close()
    # One request listing many ranges: the whole body once, not one copy per range.
    status, head, data = http(port, b'GET /viewer.js HTTP/1.1\r\nHost: x\r\nConnection: close\r\nRange: bytes=' +
                              b','.join([b'0-'] * 1000) + b'\r\n\r\n')
    whole = len(get('/viewer.js')[2])
    r = row('`Range:` with 1,000 ranges on /viewer.js', status, {200}, f'{len(data):,} bytes: the whole file once')
    if len(data) > whole:
        r.problems.append(f'{len(data)} bytes, the file is {whole}')
    status, head, data = http(port, b'GET /api/extract?iso=0&eps=0 HTTP/1.1\r\nHost: x\r\nConnection: close\r\n'
                              b'Range: bytes=' + b','.join([b'0-'] * 2600) + b'\r\n\r\n', timeout=30)
    r = row('`Range:` with 2,600 ranges on /api/extract', status, {200}, f'{len(data):,} bytes: the mesh once')
    if vm_kb(p.pid, 'VmHWM') > 1 << 20:
        r.problems.append(f'server peak {vm_kb(p.pid, "VmHWM") >> 10} MB')
    # 100 connections dripping a header line a second: each loses its connection at its request's
    # deadline (5 s), however often it sends; normal requests are answered meanwhile.
    drips = []
    for _ in range(100):
        s = socket.create_connection(('127.0.0.1', port))
        s.sendall(b'GET /api/info HTTP/1.1\r\n')
        drips.append(s)
    closed, worst, start = set(), 0.0, time.monotonic()
    for second in range(8):
        time.sleep(1)
        for i, s in enumerate(drips):
            try:
                s.sendall(b'X-Drip-%d: y\r\n' % second)
            except OSError:
                closed.add(i)
        t = time.monotonic()
        if get('/api/info')[0] != 200:
            worst = 999
        worst = max(worst, time.monotonic() - t)
    for s in drips:
        s.close()
    r = row('100 connections dripping a header line a second for 8 s; a normal request each second', 200,
            {200}, f'slowest normal answer {1e3 * worst:.0f} ms; {len(closed)} of 100 drips cut by the server', 109)
    if worst > 2:
        r.problems.append(f'a normal request took {worst:.1f} s')
    if len(closed) < 100:
        r.problems.append(f'{100 - len(closed)} drips still connected after 8 s')
    # 200 extraction requests at once.
    rss_before = vm_kb(p.pid, 'VmRSS')
    results = []
    lock = threading.Lock()

    def one():
        try:
            status, head, _ = get('/api/extract?iso=0&eps=0')
        except OSError as e:
            status, head = str(e), ''
        with lock:
            results.append((status, 'Retry-After: 1' in head))
    threads = [threading.Thread(target=one) for _ in range(200)]
    start = time.monotonic()
    for t in threads:
        t.start()
    for t in threads:
        t.join()
    seconds = time.monotonic() - start
    grown = (vm_kb(p.pid, 'VmHWM') - rss_before) / 1024
    ok = sum(1 for s, _ in results if s == 200)
    busy = sum(1 for s, retry in results if s == 503 and retry)
    r = row('200 extraction requests at once', f'200 x{ok}, 503 x{busy}', {f'200 x{ok}, 503 x{busy}'},
            f'all answered in {seconds:.1f} s; server RSS +{grown:.0f} MB', 200)
    if ok + busy != 200:
        r.problems.append(f'other answers: {[s for s, _ in results if s not in (200, 503)][:5]}')
    if grown > 400:
        r.problems.append(f'server grew {grown:.0f} MB')
    r.max_rss_mb = vm_kb(p.pid, 'VmHWM') / 1024
    # 60 clients asking for big meshes and never reading them (a store of embryo, eps 16: about 39 MB
    # a mesh): the server holds them against its response budget, refuses (503) beyond it, and drops
    # each client behind the pace.
    embryo = os.path.join(ROOT, '..', 'shared', 'data', 'embryo_256x256x256_uint8.raw')
    big = os.path.join(work, 'embryo-serve.isotope')
    subprocess.run([iso, 'convert', embryo, big, '--quiet'], check=True)
    q = subprocess.Popen([iso, 'serve', big, '--port', '0', '-q', '--cache-mb', '64'], stdout=subprocess.PIPE,
                         stderr=subprocess.STDOUT)
    big_port = int(q.stdout.readline().decode().rsplit(':', 1)[1].strip().strip('/'))
    stalled = []
    for _ in range(60):
        s = socket.create_connection(('127.0.0.1', big_port))
        s.setsockopt(socket.SOL_SOCKET, socket.SO_RCVBUF, 4096)
        s.sendall(b'GET /api/extract?iso=64.5&eps=16 HTTP/1.1\r\nHost: x\r\n\r\n')
        stalled.append(s)
    time.sleep(15)
    held = vm_kb(q.pid, 'VmRSS') >> 10
    for s in stalled:
        s.close()
    # The bodies go once the server has seen each client leave, which takes longer than the clients'
    # going when the machine is slow (4 s, then 540 -> 108 MB, in an hour when 3 s fell short): the
    # memory must come down within 15 s.
    left = time.monotonic()
    after = vm_kb(q.pid, 'VmRSS') >> 10
    while after > 400 and time.monotonic() - left < 15:
        time.sleep(0.5)
        after = vm_kb(q.pid, 'VmRSS') >> 10
    waited = time.monotonic() - left
    peak = vm_kb(q.pid, 'VmHWM') >> 10
    r = row('60 clients ask for 39 MB meshes and never read them', 'bounded', {'bounded'},
            f'server {held} MB while they wait, peak {peak} MB, {after} MB {waited:.1f} s after they left', 60)
    if peak > 1024 or after > 400:
        r.problems.append(f'peak {peak} MB, {after} MB after')
    r.max_rss_mb = peak
    q.send_signal(signal.SIGINT)
    q.wait(timeout=10)
    status, _, _ = get('/api/info')
    row('still serving after all of the above', status, {200})
    p.send_signal(signal.SIGINT)
    try:
        rc = p.wait(timeout=10)
    except subprocess.TimeoutExpired:
        p.kill()
        rc = 'hang'
    r = row('Ctrl-C stops the server', f'exit {rc}', {'exit 0'})


PYTHON_CASES = [
    ('`spacing=(nan, 1, 1)`', "isotope.extract(a, 30, spacing=(float('nan'), 1, 1))", 'ValueError',
     'must be 3 finite numbers > 0'),
    ('`origin=(inf, 0, 0)`', "isotope.extract(a, 30, origin=(float('inf'), 0, 0))", 'ValueError',
     'must be 3 finite numbers'),
    ('`spacing=(1e300, 1, 1)`', 'isotope.extract(a, 30, spacing=(1e300, 1, 1))', 'ValueError', 'float32 coordinates'),
    ('`convert` with `spacing=(0, 1, 1)`', 'isotope.convert(a, "c.isotope", spacing=(0, 1, 1))', 'ValueError',
     'must be 3 finite numbers > 0'),
    ('`max_triangles=0`', 'isotope.extract(a, 30, max_triangles=0)', 'OptionError', 'must be an integer in 1 ..'),
    ('`max_triangles=1000, eps=2`', 'isotope.extract(a, 30, max_triangles=1000, eps=2)', 'OptionError',
     'not both'),
    ('`threads=-1`', 'isotope.extract(a, 30, threads=-1)', 'OptionError', 'threads must be an integer in 0 .. 4096'),
    ('`threads=2**70`', 'isotope.extract(a, 30, threads=2 ** 70)', 'OptionError',
     'threads must be an integer in 0 .. 4096'),
    ('`dims=(2**63, 2, 2)`', 'isotope.extract("x.raw", 30, dims=(2 ** 63, 2, 2), type="uint8")', 'OptionError',
     'dims must look like'),
    ('a progress callback that uses its own Source',
     'exec("s = None\\ndef cb(f):\\n    s.info\\ns = isotope.Source(a, progress=cb)\\ns.extract(30, eps=4)")',
     'RuntimeError', 'may not use the Source that reports to it'),
    ('a NaN in a float32 array', 'b = a.astype("float32"); b[1, 2, 3] = float("nan"); isotope.extract(b, 30)',
     'ValueError', 'at (x,y,z) = (3,2,1) is not finite'),
    ('a 1x1x1 array', 'isotope.extract(a[:1, :1, :1], 30)', 'ValueError', 'volume dimensions 1x1x1'),
    ('a copy that fails for memory (`RLIMIT_AS`)',
     'import resource; big = np.ones((256, 256, 512), np.uint8); used = int(open("/proc/self/statm").read().split()[0])'
     ' * resource.getpagesize(); resource.setrlimit(resource.RLIMIT_AS, (used + (96 << 20), resource.RLIM_INFINITY));'
     ' isotope.extract(big, 0.5)', 'MemoryError', ''),
]


def python_module(python, work):
    """The Python module as a hostile caller would use it: one child per case, each must raise its
    exception with the library's words (and never hang, crash or write)."""
    d = os.path.join(work, 'python')
    os.makedirs(d)
    neghip = os.path.join(ROOT, '..', 'shared', 'data', 'neghip_66x66x66_uint8.raw')
    for case, code, exception, words in PYTHON_CASES:
        r = add(Row('Python module', case))
        if not python:
            r.got, r.message = 'not run', 'no --python given'
            r.problems.append('not run')
            continue
        script = (f'import sys, numpy as np, isotope\na = np.fromfile({neghip!r}, np.uint8).reshape(66, 66, 66)\n'
                  f'try:\n    {code}\nexcept {exception if exception != "OptionError" else "isotope.OptionError"}'
                  f' as e:\n    print("raised", type(e).__name__ + ":", e)\n    sys.exit(0)\nprint("returned")\n')
        before = listing(d)
        rc, out, secs, rss = run([python, '-c', script], cwd=d)
        r.max_rss_mb, r.max_seconds = rss, secs
        first = out.strip().splitlines()[-1] if out.strip() else ''
        r.got = f'{exception}' if rc == 0 and first.startswith('raised') else (
            'hang' if rc == 'hang' else f'exit {rc}')
        r.message = first.replace('raised ', '', 1)
        if rc != 0 or not first.startswith('raised') or words not in first:
            r.problems.append(f'{rc}: {out[-300:]}')
        if listing(d) != before:
            r.problems.append('wrote a file')
    r = add(Row('Python module', 'another thread writes NaN into a borrowed float32 array during an extraction', 0))
    r.got, r.message = 'documented', 'a borrowed array must not change while a call reads it (README, Python)'


def memory_shapes(iso, work):
    """A volume's memory follows its voxels, not its longest axis (engine/hierarchy/store_layout.h)."""
    d = os.path.join(work, 'shapes')
    os.makedirs(d)
    import math
    for name, dims in (('long', (500000, 2, 2)), ('flat', (2000, 2000, 2))):
        raw = os.path.join(d, f'{name}_{dims[0]}x{dims[1]}x{dims[2]}_uint8.raw')
        row_values = bytes(int(128 + 100 * math.sin(x / 50)) for x in range(dims[0]))
        open(raw, 'wb').write(row_values * (dims[1] * dims[2]))
        r = add(Row('Memory', f'`extract --eps 1` of a {dims[0]}x{dims[1]}x{dims[2]} uint8 volume '
                              f'({dims[0] * dims[1] * dims[2] / 1e6:.0f} MB)'))
        rc, out, secs, rss = run([iso, 'extract', raw, '--iso', '127.5', '--eps', '1', '-q', '-o',
                                  os.path.join(d, 'm.ply')])
        r.got, r.max_rss_mb, r.max_seconds = f'exit {rc}', rss, secs
        r.message = f'peak RSS {rss:.0f} MB in {secs:.1f} s'
        if rc != 0 or rss > 600:
            r.problems.append(f'exit {rc}, {rss:.0f} MB: {out[:200]}')
        os.remove(raw)


def fuzz_rows(stats):
    if not stats or not os.path.exists(stats):
        return
    for line in open(stats):
        target, runs, seconds = line.split()
        r = add(Row('Fuzzing (libFuzzer, ASan+UBSan; `scripts/fuzz.sh`)', f'`fuzz/fuzz_{target}.cpp`', int(runs)))
        r.got, r.message = f'{int(runs):,} inputs in {seconds} s', 'no finding'


def write_table(out, fuzz_seconds):
    lines = ['# Reliability: what was tried, and what each gets', '',
             '<!-- Written by scripts/reliability.sh; do not edit by hand. -->', '',
             'isotope tried as a hostile user would (`bash scripts/reliability.sh`, which builds, fuzzes every '
             f'parser for {fuzz_seconds} s and runs `scripts/reliability.py`). Every row must hold: a clear message '
             'and exit 1 (2 for a usage error) or the HTTP status of docs/SERVE.md, nothing written, the inputs '
             'unchanged, no crash, no hang (each command within 30 s), memory bounded (every command below 1 GB '
             'peak RSS). "Tried" counts commands (or requests, or fuzz inputs). The messages are the first line '
             'the command printed, paths shortened. The golden reject files and their expected messages are in '
             '`tests/golden` (`tests/cli/reject_test.cpp` runs them in CI); the server limits are in docs/SERVE.md.',
             '', '## The policies the table checks', '',
             '- **Outputs** (io/file/atomic_file.h): a new path or a regular file is written to a temporary file in '
             'its directory and renamed when complete (a full disk leaves the old file); a symbolic link is '
             'followed and the file it names replaced in its own directory; a device, FIFO, socket or directory '
             'is refused, never replaced; an output that is the same file as an input (device and inode) or as '
             'another output is refused before any work. `extract` finishes the mesh and the report on disk '
             'before it renames either.',
             '- **Inputs** (io/file/input_file.h): regular files only; a FIFO or a device is refused by name before '
             'it is opened.',
             '- **Stores** (io/store/store_format.cpp, docs/FORMAT.md): one validation of the header and of each '
             'band directory on every reader path (extract, serve, info, verify): every header field within its '
             'documented range, reserved bytes zero, directory entries inside the brick area and not '
             'overlapping; sizes and offsets from the file checked with io/file/checked_size.h, never by a sum that '
             'can wrap; nothing allocated by a file field before that check. Every byte of a store is under a '
             'checksum; `verify` also checks what a checksum cannot (bricks against their neighbours and bands).',
             '- **Server** (docs/SERVE.md, Limits): 128 workers; 5 s for a whole request head and body (a first '
             'request from its accept), and 5 s idle; a response taken at 64 KB/s on average after its first 10 s, or '
             'the connection is closed; '
             'Range headers ignored (the whole body once); 512 MB of responses in flight, 503 beyond; 1 KB '
             'bodies, 8 KB request lines and headers, 2 extractions at once and 16 waiting, 503 with Retry-After '
             'beyond.',
             '- **Output folders** (io/file/output_folder.h, `--parts`): a new, empty or earlier `--parts` folder '
             '(its manifest lists what isotope wrote), nothing else; never one that holds the input; of an earlier '
             'one only the files its manifest lists are removed.',
             '- **Python module**: arrays and options checked by the same library checks as files and the command '
             'line, with the same words.',
             '- **Command line** (tools/commands.h): every numeric option checked at parse time, with a message '
             'that names the option and its range; exit 2.',
             '- **Across ranks** (docs/DISTRIBUTED.md): under `mpirun`, a rank whose work fails stops every rank at '
             'the next step they share, and rank 0 prints the failing rank\'s message once; a killed rank ends the '
             'job (the others remove their temporary files on SIGTERM); nothing is left behind either way.',
             '', '## What was tried', '',
             '| | what | tried | gets | message | holds |', '|---|---|---:|---|---|---|']
    category = None
    for r in rows:
        c = r.category if r.category != category else ''
        category = r.category
        # Paths shortened to their last component: the scratch folder's name changes every run.
        msg = re.sub(r'(?<![\w.])/(?:[^\s/:]+/)+', '', r.message).replace('|', '\\|')
        if len(msg) > 110:
            msg = msg[:107] + '...'
        verdict = 'yes' if r.ok() else 'NO: ' + '; '.join(r.problems)[:200]
        if r.got == 'not run':
            verdict = 'not run'
        lines.append(f'| {c} | {r.case} | {r.tried:,} | {r.got} | {msg} | {verdict} |')
    bad = [r for r in rows if not r.ok()]
    lines += ['', f'{len(rows)} rows, {sum(r.tried for r in rows):,} tries; '
              f'{"every row holds" if not bad else str(len(bad)) + " rows do NOT hold"}. '
              f'Largest peak RSS of a command: {max(r.max_rss_mb for r in rows):.0f} MB; '
              f'slowest: {1e3 * max(r.max_seconds for r in rows):.0f} ms.', '']
    open(out, 'w').write('\n'.join(lines))
    return bad


def main():
    a = argparse.ArgumentParser(description=__doc__.split('\n')[0])
    a.add_argument('--isotope', default=os.path.join(ROOT, 'build', 'tools', 'isotope'))
    a.add_argument('--fuzz-stats', default='')
    a.add_argument('--fuzz-seconds', default='60')
    a.add_argument('--random', type=int, default=400, help='random store corruptions')
    a.add_argument('--python', default='', help='a Python with the isotope module installed (its rows)')
    a.add_argument('--out', default=os.path.join(ROOT, 'docs', 'RELIABILITY.md'))
    args = a.parse_args()
    iso = os.path.abspath(args.isotope)
    python = os.path.abspath(args.python) if args.python else ''  # not resolved: a venv's python is a link
    with tempfile.TemporaryDirectory() as work:
        volume = bad_paths(iso, work)
        reject_files(iso, work)
        store = random_corruptions(iso, work, volume, args.random)
        cli_numbers(iso, work, volume)
        distributed(iso, work)
        http_abuse(iso, work, store)
        python_module(python, work)
        memory_shapes(iso, work)
    fuzz_rows(args.fuzz_stats)
    bad = write_table(args.out, args.fuzz_seconds)
    for r in bad:
        print(f'reliability: does not hold: {r.category}: {r.case}: {"; ".join(r.problems)}', file=sys.stderr)
    print(f'reliability: {len(rows)} rows, {len(bad)} failing; table in {args.out}')
    return 1 if bad else 0


if __name__ == '__main__':
    sys.exit(main())
