#!/usr/bin/env python3
"""Two builds of the octmesh command side by side, phase by phase.

Runs `mpirun -np P BIN mesh SURFACE --level L --keep inside --stats` with the
"before" and the "after" binary in alternating order for every round, so both
see the same slow and fast spells of the machine, and prints the median of
each phase's time (seconds, maximum over ranks), of the total and of the peak
memory (MiB per rank), with the ratio after / before.

    python3 tools/bench/ab_compare.py --before OLD/target/release/octmesh \
        --after target/release/octmesh --rounds 5
"""
import argparse
import json
import os
import statistics
import subprocess
import tempfile

PHASES = ['read', 'construct', 'refine', 'balance', 'classify', 'ghost', 'nodes',
          'numbering', 'connectivity']


def main():
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument('--before', required=True, help='the octmesh binary to compare against')
    ap.add_argument('--after', default='target/release/octmesh', help='the new binary')
    ap.add_argument('--rounds', type=int, default=5)
    ap.add_argument('--cases', default='sphere:10:1,sphere:10:2,../shared/data/bunny.stl:10:2',
                    help='comma-separated SURFACE:LEVEL:RANKS')
    a = ap.parse_args()
    env = dict(os.environ, OMPI_ALLOW_RUN_AS_ROOT='1', OMPI_ALLOW_RUN_AS_ROOT_CONFIRM='1',
               OMPI_MCA_rmaps_base_oversubscribe='1')
    bins = {'before': a.before, 'after': a.after}
    tmp = tempfile.mkdtemp()
    for case in a.cases.split(','):
        surf, lvl, np_ = case.rsplit(':', 2)
        res = {k: {p: [] for p in PHASES + ['total', 'peak']} for k in bins}
        for r in range(a.rounds):
            for k in (['before', 'after'] if r % 2 == 0 else ['after', 'before']):
                out = os.path.join(tmp, f'{k}.json')
                subprocess.run(['mpirun', '-np', np_, bins[k], 'mesh', surf, '--level', lvl,
                                '--keep', 'inside', '--quiet', '--stats', out], env=env, check=True)
                j = json.load(open(out))
                t = j['timings']
                for p in PHASES:
                    res[k][p].append(t.get(p, 0))
                res[k]['total'].append(sum(t.values()))
                res[k]['peak'].append(j['peak_rss_bytes'] / 2**20)
        print(f'\n{os.path.basename(surf)} level {lvl}, {np_} rank(s), {a.rounds} alternating '
              'rounds, medians (s; peak MiB):')
        print(f'  {"phase":<13}{"before":>10}{"after":>10}{"after/before":>14}')
        for p in PHASES + ['total', 'peak']:
            b, x = statistics.median(res['before'][p]), statistics.median(res['after'][p])
            print(f'  {p:<13}{b:>10.4f}{x:>10.4f}{(x / b if b else float("nan")):>14.3f}')


if __name__ == '__main__':
    main()
