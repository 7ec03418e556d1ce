# Per trial of an `eval --trace aSEED.trace --grader-state --out aSEED.jsonl` run (log in aSEED.log):
# where the peg tip came down to the hole's mouth, split into the hole's estimate error (the last
# trusted fit in the log against the hidden block) and the rest (the peg in the hand, the tool;
# in the tool's frame). Usage: python3 arrival.py 5000 (beside search.py).
import sys,math,collections,re
from search import R,load,tip_and_top,at_mouth
s=sys.argv[1]
res,tr=load(f'a{s}.trace',f'a{s}.jsonl')
# The trusted fits of the block per trial, from the debug log: a trial's first look is the first
# "look 1:" line after a line of another look.
est=collections.defaultdict(list); t=-1; prev=None
for l in open(f'a{s}.log'):
    m=re.search(r'twin actor, look (\d+):',l)
    if m:
        if m.group(1)=='1' and prev!='1': t+=1
        prev=m.group(1)
    m=re.search(r'hole_block seen at \(([-0-9.]+), ([-0-9.]+)\).*score (-?[0-9]+)',l)
    if m and int(m.group(3))>0: est[t].append((float(m.group(1)),float(m.group(2))))
for t in sorted(tr):
    for d in tr[t]:
        tip,top=tip_and_top(d)
        if at_mouth(tip,top): break
    else: continue
    if not est[t]: continue
    hb=d['grader']['objects']['hole_block']
    e=est[t][-1]; he=((e[0]-hb[0])*1000,(e[1]-hb[1])*1000)
    arr=((tip[0]-top[0])*1000,(tip[1]-top[1])*1000)
    # in-hand+tracking = arrival - hole error ; express in tool frame
    Mt=R(d['tool_quat']); rest=(arr[0]-he[0],arr[1]-he[1])
    rt=[Mt[0][c]*rest[0]+Mt[1][c]*rest[1] for c in range(2)]
    print(s,t,'S' if res[t]['success'] else 'F','arrive %5.1f %5.1f |%4.1f| holeerr %5.1f %5.1f |%4.1f| rest(tool xy) %5.1f %5.1f |%4.1f|'%(arr[0],arr[1],math.hypot(*arr),he[0],he[1],math.hypot(*he),rt[0],rt[1],math.hypot(*rt)))
