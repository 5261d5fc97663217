#!/usr/bin/env python3
"""Splits samples-bench's one-way latency into the stages a kernel trace can see.

Input: `perf script --ns -F comm,pid,tid,cpu,time,event,trace` of a trace taken with
`perf record -k CLOCK_MONOTONIC` (events below) on stdin, and the file samples-bench
wrote with SAMPLES_BENCH_STAMPS (`receiver-pid k send-stamp receive-time`, ns, the
same clock). Each receiver process is one phase (run order: 100 Hz, 1 kHz, back to
back; per phase the receivers named on the command line, in samples-bench's order).

Stages of one message (µs):
  A  send stamp -> sender enters sendto   (the sender's user-space work)
  B  sendto -> receiver woken             (kernel send path up to the wake-up)
  C  woken -> receiver on a CPU           (scheduler)
  D  on a CPU -> its syscall returns      (epoll_wait / recvfrom return path)
  E  syscall return -> sample in hand     (the receiver's user-space work)
usage: wake_stages.py STAMPS PHASE-NAME,... < perf-script-output
"""
import bisect
import collections
import re
import sys

WARMUP = 50
LINE = re.compile(r'^\s*(\S+)\s+(\d+)/(\d+)\s+\[(\d+)\]\s+([\d.]+):\s+(\S+):(.*)$')


def main():
    stamps = collections.OrderedDict()
    with open(sys.argv[1]) as f:
        for line in f:
            pid, k, t0, t1 = map(int, line.split())
            stamps.setdefault(pid, []).append((k, t0, t1))
    names = sys.argv[2].split(',') if len(sys.argv) > 2 else []
    ev = collections.defaultdict(list)
    for line in sys.stdin:
        m = LINE.match(line)
        if not m:
            continue
        _comm, _pid, tid, _cpu, t, name, rest = m.groups()
        t = int(round(float(t) * 1e9))
        if name == 'sched:sched_waking':
            ev[('waking', int(re.search(r' pid=(\d+)', rest).group(1)))].append(t)
        elif name == 'sched:sched_switch':
            ev[('run', int(re.search(r'next_pid=(\d+)', rest).group(1)))].append(t)
        else:
            ev[(name.split(':')[1], int(tid))].append(t)
    for v in ev.values():
        v.sort()
    # The sender: the thread outside the receivers that entered sendto most often.
    sender = max((len(v), k[1]) for k, v in ev.items()
                 if k[0] == 'sys_enter_sendto' and k[1] not in stamps)[1]

    def after(kind, pid, t):
        a = ev.get((kind, pid), [])
        i = bisect.bisect_left(a, t)
        return a[i] if i < len(a) else None

    for idx, (pid, rows) in enumerate(stamps.items()):
        name = names[idx] if idx < len(names) else str(pid)
        woke_in = 'sys_exit_epoll_wait' if name.startswith('iox') else 'sys_exit_recvfrom'
        st = collections.defaultdict(list)
        for k, t0, t1 in rows:
            if k < WARMUP:
                continue
            s = after('sys_enter_sendto', sender, t0)
            w = s and after('waking', pid, s)
            r = w and after('run', pid, w)
            x = r and after(woke_in, pid, r)
            if None in (s, w, r, x) or x > t1:
                continue  # taken without a wake-up (queued): not this breakdown
            for key, v in (('A stamp->sendto', s - t0), ('B sendto->woken', w - s),
                           ('C woken->on cpu', r - w), ('D on cpu->syscall return', x - r),
                           ('E return->sample', t1 - x), ('total', t1 - t0)):
                st[key].append(v)
        print(f'{name} (pid {pid}): {len(st["total"])} messages woken')
        if not st:
            continue
        for key in sorted(st):
            a = sorted(st[key])
            n = len(a)
            print(f'   {key:<26} p50 {a[n // 2] / 1e3:7.2f}  p90 {a[n * 9 // 10] / 1e3:7.2f}'
                  f'  mean {sum(a) / n / 1e3:7.2f} µs')


if __name__ == '__main__':
    main()
