# Per trial of a traced eval (`--trace T --grader-state`): when the peg tip reached the mouth, how far
# from the hole's axis (mm), the peg's tilt and yaw to the hole; the least offset while searching.
# Usage: python3 search.py aSEED.trace aSEED.jsonl [all]
import json,sys,math,collections
def R(q):
    w,x,y,z=q
    return [[1-2*(y*y+z*z),2*(x*y-w*z),2*(x*z+w*y)],[2*(x*y+w*z),1-2*(x*x+z*z),2*(y*z-w*x)],[2*(x*z-w*y),2*(y*z+w*x),1-2*(x*x+y*y)]]
def ap(M,v): return [sum(M[r][c]*v[c] for c in range(3)) for r in range(3)]
def load(trace, results):
    """The trials' results by trial, and each trial's traced steps."""
    res={d['trial']:d for d in map(json.loads,open(results)) if 'trial' in d and 'success' in d}
    tr=collections.defaultdict(list)
    for l in open(trace):
        d=json.loads(l); tr[d['trial']].append(d)
    return res,tr
def tip_and_top(d):
    """A traced step's hidden peg tip and hole mouth (m, world)."""
    g=d['grader']; hb=g['objects']['hole_block']; pg=g['objects']['peg']
    Mh=R(g['object_quats']['hole_block']); Mp=R(g['object_quats']['peg'])
    top=[hb[i]+ap(Mh,[0,0,0.02])[i] for i in range(3)]
    tip=[pg[i]+ap(Mp,[0,0,-0.045])[i] for i in range(3)]
    return tip,top
def at_mouth(tip,top):
    """The tip within 3 mm above the mouth's height and 15 mm of its axis."""
    return tip[2]-top[2]<0.003 and math.hypot(tip[0]-top[0],tip[1]-top[1])<0.015
if __name__=='__main__':
    res,tr=load(sys.argv[1],sys.argv[2])
    for t in sorted(tr):
        if t not in res: continue
        if res[t]['success'] and len(sys.argv)<4: continue
        rows=[]; contact=[]
        for d in tr[t]:
            g=d['grader']; tip,top=tip_and_top(d)
            pq=g['object_quats']['peg']; tilt=math.degrees(2*math.acos(min(1,math.sqrt(pq[0]**2+pq[3]**2))))
            off=math.hypot(tip[0]-top[0],tip[1]-top[1])*1000
            yh=math.degrees(2*math.atan2(g['object_quats']['hole_block'][3],g['object_quats']['hole_block'][0]))
            Mp=R(pq); yp=math.degrees(math.atan2(Mp[1][0],Mp[0][0]))
            yaw=(yp-yh+45)%90-45
            rows.append((d['step'],off,(tip[2]-top[2])*1000,tilt,yaw))
            if at_mouth(tip,top): contact.append(rows[-1])
        if not contact: print(t,res[t]['success'],'never at the mouth; last',['%.1f'%x for x in rows[-1]]); continue
        c0=contact[0]
        print(t,res[t]['success'],'steps',res[t]['steps'],'mouth at step %d off %.1f mm tilt %.1f yaw %.1f; min off %.1f; at mouth %d steps; last off %.1f dz %.1f tilt %.1f'%(c0[0],c0[1],c0[3],c0[4],min(r[1] for r in contact),len(contact),rows[-1][1],rows[-1][2],rows[-1][3]))
