# Predicts each look of a train samrl run by the mean return of the other episodes' looks in the
# same class (leaving its own episode out) and prints the squared error per way of classing.
# usage: python3 loo.py DIR/q.json
import json,sys,math,collections
d=json.load(open(sys.argv[1])); v=d['views']
def fillc(x):
    f=x['targets_fill']*100
    return 0 if f<0.5 else (1 if f<5 else 2)
keys={'mean':lambda x:0,'azimuth':lambda x:int((x['azimuth']+3)/0.5),'fill':fillc,'look':lambda x:x['look'],
 'step+fill':lambda x:(x['step'],fillc(x)),'look+fill':lambda x:(x['look'],fillc(x))}
for name,k in keys.items():
    err=0
    for x in v:
        others=[y['return'] for y in v if y['trial']!=x['trial'] and k(y)==k(x)]
        if not others: others=[y['return'] for y in v if y['trial']!=x['trial']]
        p=sum(others)/len(others); err+=(x['return']-p)**2
    print(name, round(err/len(v),4))
c=collections.defaultdict(lambda:[0,0])
for x in v: c[(x['look'],fillc(x))][0]+=x['return']; c[(x['look'],fillc(x))][1]+=1
print(sorted((k,f'{a:.0f}/{b}') for k,(a,b) in c.items()))
