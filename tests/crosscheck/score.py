import json, os, sys
OUT = os.environ.get('XCHECK_OUT', '/tmp/xcheck')
import glob
names=[n for f in (sys.argv[1:] or [f'{OUT}/datasets.json']) for n in json.load(open(f))]
rows=[]; conf={}
for nm in names:
    d=f'{OUT}/{nm}'
    t=json.load(open(f'{d}/truth_xcheck.json')); r=json.load(open(f'{d}/report.json'))
    F=r.get('findings') or []
    named=[f for f in F if f['effect']!='unexplained']
    unexp=[f for f in F if f['effect']=='unexplained']
    te=t['effect']; place=t['joint'] or t['sensor']
    def fplace(f): return f.get('joint') or f.get('sensor')
    if te is None:
        cat='correct_negative' if not named else 'FALSE_ALARM'
        if not named and unexp: cat='false_unexplained'
    else:
        if any(f['effect']==te and fplace(f)==place for f in named):
            cat='right' if len(named)==1 else 'right+EXTRA'
        elif any(f['effect']==te for f in named): cat='WRONG_PLACE'
        elif named: cat='WRONG_EFFECT'
        elif unexp: cat='MISSED(unexplained)'
        else: cat='MISSED'
    conf.setdefault((te or 'none'),{}).setdefault(cat,0); conf[te or 'none'][cat]+=1
    geo=r['stats']['test']['after']['rms_mm']
    fs='; '.join(f"{f['effect']} j/s={fplace(f)} mag={f.get('magnitude')} {f.get('unit','')} test {f.get('test_rms_before_mm',float('nan')):.4f}->{f.get('test_rms_after_mm',float('nan')):.4f}" for f in F) or '-'
    rows.append((nm,te,place,t['magnitude'],t['effect_rms_mm'],t['point_noise_mm'],geo,cat,fs))
for row in rows:
    print(f"{row[0]:28s} truth={row[1]} @{row[2]} mag={row[3]:.4g} rms={row[4]:.3f} noise={row[5]:.4f} geoTest={row[6]:.4f} -> {row[7]}\n      tool: {row[8]}")
print()
for k,v in conf.items(): print(f"{k:20s}",v)
