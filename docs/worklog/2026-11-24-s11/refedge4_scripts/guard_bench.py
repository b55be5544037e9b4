"""guard_bench.py BASE_RESULTS NEW_RESULTS: does the new rule flatter any method? Per method, the mean over frames of
MSE / RMSE against the HQ reference ('hq') and against the truth on the reference's pixels ('truth'), in the base
results and the new ones, and the relative change in each scoring (a rule that flatters a method moves its
reference-scored number more than its truth-scored one). Then bench.summary.ranking_check on the new results: same
order by MSE and RMSE, and the pairs decided wrongly."""
import sys
import pandas as pd
sys.path.insert(0, '/work/wt/refedge4')
from bench.summary import ranking_check

a, b = (pd.read_parquet(f'{p}/results.parquet') for p in sys.argv[1:3])
for metric in ('mse_mm2', 'rmse_mm'):
    print(metric)
    for key in sorted(set(a['method_key'])):
        v = {}
        for name, df in (('base', a), ('new', b)):
            for ref in ('hq', 'truth'):
                s = df[(df['method_key'] == key) & (df['reference'] == ref) & (df['metric'] == metric) & df['bin_lo_m'].isna()]
                v[name, ref] = s.groupby('frame')['value'].mean().mean()
        print(f"  {key.split('(')[0]:16s} hq {v['base', 'hq']:8.2f} -> {v['new', 'hq']:8.2f} ({v['new', 'hq'] / v['base', 'hq'] - 1:+.1%})   "
              f"truth {v['base', 'truth']:8.2f} -> {v['new', 'truth']:8.2f} ({v['new', 'truth'] / v['base', 'truth'] - 1:+.1%})")
for name, df in (('base', a), ('new', b)):
    rc = ranking_check(df)
    for m, r in rc.items():
        print(f"{name} {m}: same order {r['same']} ({r['order']['hq']} vs {r['order']['truth']}), wrong pairs {r['wrong']}")
