#!/usr/bin/env python3
"""Tries isotope as a hostile user would and writes the table of docs/RELIABILITY.md: bad paths,
bad volumes, corrupted stores by kind (the golden reject files of tests/reject and random
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
REJECT = os.path.join(ROOT, 'tests', 'reject')
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
    first = out.strip().splitlines()[0] if out.strip() else ''
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
        r = add(Row(category, f'`tests/reject/{f}`'))
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
    status, _, _ = get('/api/info')
    row('still serving after all of the above', status, {200})
    p.send_signal(signal.SIGINT)
    try:
        rc = p.wait(timeout=10)
    except subprocess.TimeoutExpired:
        p.kill()
        rc = 'hang'
    r = row('Ctrl-C stops the server', f'exit {rc}', {'exit 0'})


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
             '`tests/reject` (`tests/reject_test.cpp` runs them in CI); the server limits are in docs/SERVE.md.',
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
             '- **Server** (docs/SERVE.md, Limits): 64 workers, 5 s read and idle timeouts, 1 KB bodies, 8 KB '
             'request lines and headers, 2 extractions at once and 16 waiting, 503 with Retry-After beyond.',
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
    a.add_argument('--out', default=os.path.join(ROOT, 'docs', 'RELIABILITY.md'))
    args = a.parse_args()
    iso = os.path.abspath(args.isotope)
    with tempfile.TemporaryDirectory() as work:
        volume = bad_paths(iso, work)
        reject_files(iso, work)
        store = random_corruptions(iso, work, volume, args.random)
        cli_numbers(iso, work, volume)
        distributed(iso, work)
        http_abuse(iso, work, store)
    fuzz_rows(args.fuzz_stats)
    bad = write_table(args.out, args.fuzz_seconds)
    for r in bad:
        print(f'reliability: does not hold: {r.category}: {r.case}: {"; ".join(r.problems)}', file=sys.stderr)
    print(f'reliability: {len(rows)} rows, {len(bad)} failing; table in {args.out}')
    return 1 if bad else 0


if __name__ == '__main__':
    sys.exit(main())
