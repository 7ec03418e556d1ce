# looks3.py NAME: per trial, each look's fit of the block (mm from where the block ended the
# trial) and the actor's info lines, from NAME.log.gz (a --log-level debug eval log) and NAME.jsonl
import json,re,math,sys,gzip
name=sys.argv[1]
trials=[json.loads(l) for l in open(name+'.jsonl') if '"success"' in l]
chunks=[]
for l in gzip.open(name+'.log.gz','rt'):
    if re.search(r'look 1: peg ',l): chunks.append([])
    if chunks: chunks[-1].append(l)
for t,ch in zip(trials,chunks):
    g=t['grader']['objects']['hole_block']
    looks=[]
    for l in ch:
        m=re.search(r'look (\d+): hole_block (seen|NOT seen|fitted) at \(([-\d.]+), ([-\d.]+)\)',l)
        if m: looks.append((int(m.group(1)), m.group(2)[:3], round(1000*math.hypot(float(m.group(3))-g[0],float(m.group(4))-g[1]))))
        m=re.search(r'info twin actor: (.*)',l)
        if m: looks.append(m.group(1)[:70])
    print('trial',t['trial'],t['success'],t['steps'],'block end',[round(x,3) for x in g[:2]])
    for x in looks: print('   ',x)
