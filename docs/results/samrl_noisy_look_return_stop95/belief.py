# belief.py NAME: per trial, the first look's fit of each object (NAME.log, or its look lines in
# NAME.looks.log.gz) against the block's place at the trial's end (the grader's state in NAME.jsonl)
import json,re,sys,math,gzip,os
name=sys.argv[1]
trials=[json.loads(l) for l in open(name+'.jsonl') if '"success"' in l]
fits={'peg':[],'hole_block':[]}
pat=re.compile(r'look 1: (\w+) (seen|NOT seen) at \(([-\d.]+), ([-\d.]+)\), (\d+) points explained, (\d+) not')
log=name+'.log' if os.path.exists(name+'.log') else name+'.looks.log.gz'
for l in (gzip.open(log,'rt') if log.endswith('.gz') else open(log)):
    m=pat.search(l)
    if m: fits[m.group(1)].append((m.group(2)=='seen',float(m.group(3)),float(m.group(4)),int(m.group(5)),int(m.group(6))))
assert len(fits['hole_block'])==len(trials),(len(fits['hole_block']),len(trials))
rows=[]
for t,fb,fp in zip(trials,fits['hole_block'],fits['peg']):
    g=t['grader']['objects']['hole_block']
    e=math.hypot(fb[1]-g[0],fb[2]-g[1])*1000
    rows.append((t['trial'],t['success'],fb[0],round(e,1),fb[3],fb[4],fp[0]))
for r in rows: print(r)
seen=[r for r in rows if r[2]]
print(name,'successes',sum(r[1] for r in rows),'block seen',len(seen),'median err seen',sorted(r[3] for r in seen)[len(seen)//2] if seen else None,
 'err>10mm among seen',sum(r[3]>10 for r in seen),'peg seen',sum(r[6] for r in rows))
