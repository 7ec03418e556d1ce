# How far a mesh (OBJ, in its body frame) lies from itself turned a quarter and a half turn about its
# body origin and about its outline's middle (vertices against points on its triangles).
# usage: python3 sym.py MESH.obj
import sys,math
V=[];F=[]
for l in open(sys.argv[1]):
    if l.startswith('v '): V.append(tuple(map(float,l.split()[1:4])))
    elif l.startswith('f '): F.append([int(x.split('/')[0])-1 for x in l.split()[1:4]])
P=list(V)
for a,b,c in F:
    A,B,C=V[a],V[b],V[c]
    P.append(tuple((A[i]+B[i]+C[i])/3 for i in range(3)))
    for X,Y in ((A,B),(B,C),(C,A)): P.append(tuple((X[i]+Y[i])/2 for i in range(3)))
# grid hash for nearest
cell=0.003; grid={}
for p in P: grid.setdefault((int(math.floor(p[0]/cell)),int(math.floor(p[1]/cell)),int(math.floor(p[2]/cell))),[]).append(p)
def near(q):
    k=(int(math.floor(q[0]/cell)),int(math.floor(q[1]/cell)),int(math.floor(q[2]/cell)))
    best=1e9
    for dx in (-1,0,1):
     for dy in (-1,0,1):
      for dz in (-1,0,1):
        for p in grid.get((k[0]+dx,k[1]+dy,k[2]+dz),()):
            d=(p[0]-q[0])**2+(p[1]-q[1])**2+(p[2]-q[2])**2
            if d<best: best=d
    return math.sqrt(best) if best<1e9 else cell*1.5
xs=[v[0] for v in V]; ys=[v[1] for v in V]
mid=((min(xs)+max(xs))/2,(min(ys)+max(ys))/2)
size=max(max(xs)-min(xs),max(ys)-min(ys))
print('vertices',len(V),'outline middle (mm)',round(mid[0]*1e3,2),round(mid[1]*1e3,2),'size mm',round(size*1e3,1))
for name,c in (('origin',(0,0)),('middle',mid)):
    for turns in (4,2):
        ang=2*math.pi/turns; co,si=math.cos(ang),math.sin(ang)
        d=[]
        for v in V:
            x,y=v[0]-c[0],v[1]-c[1]
            d.append(near((c[0]+co*x-si*y,c[1]+si*x+co*y,v[2])))
        d.sort()
        print(name,turns,'median %.2f mm, 90%% %.2f, 95%% %.2f, max %.2f'%(d[len(d)//2]*1e3,d[int(.9*len(d))]*1e3,d[int(.95*len(d))]*1e3,d[-1]*1e3))
