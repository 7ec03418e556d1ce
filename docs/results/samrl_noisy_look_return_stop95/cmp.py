# cmp.py A.jsonl B.jsonl: success of each, trial by trial, won/lost and a two-sided sign test
import json,sys,math
def load(f):
    out={}
    for l in open(f):
        j=json.loads(l)
        if 'success' in j: out[(j.get('level'),j['trial'])]=j['success']
    return out
a=load(sys.argv[1]); b=load(sys.argv[2])
common=sorted(set(a)&set(b))
sa=sum(a[k] for k in common); sb=sum(b[k] for k in common)
w=sum(a[k] and not b[k] for k in common); l=sum(b[k] and not a[k] for k in common)
n=w+l; p=min(1,2*sum(math.comb(n,i) for i in range(0,min(w,l)+1))/2**n) if n else 1
print(f"{len(common)} trials: A {sa}, B {sb}; A won {w}, lost {l}; sign test p = {p:.3g}")
