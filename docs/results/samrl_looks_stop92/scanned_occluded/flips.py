# Lists, per trial of an eval log, the hole block's turn at each look (from the twin's own), and counts the
# trials whose turn jumped by more than 45 deg between two looks. usage: python3 flips.py LOG (its .jsonl beside it)
import re,sys,json,gzip
f=sys.argv[1]
t=-1;prev=None;turns={}
for line in (gzip.open(f,'rt') if f.endswith('.gz') else open(f)):
    m=re.search(r'twin actor, look (\d+):',line)
    if m:
        if m.group(1)=='1' and prev!='1': t+=1
        prev=m.group(1)
    m2=re.search(r'hole_block seen at .*believed turned ([-\d.]+) deg',line)
    if m2: turns.setdefault(t,[]).append(float(m2.group(1)))
rows={r['trial']:r for r in map(json.loads,open(f.replace('.log.gz','.jsonl').replace('.log','.jsonl'))) if 'trial' in r}
nf=0;fl=0;ff=0
for t,r in sorted(rows.items()):
    ts=turns.get(t,[])
    flip=any(abs(((b-a+180)%360)-180)>45 for a,b in zip(ts,ts[1:]))
    nf+=flip; ff+= flip and not r['success']; fl+= not r['success']
    if flip or not r['success']: print(t, r['success'], [round(x) for x in ts])
print('trials with a flip',nf,'failures',fl,'failures with a flip',ff)
