#!/usr/bin/env python3
# Independent 40-digit Lloyd-Max references for src/stats/lloyd_max.rs tests (mpmath):
# python3 scripts/lloyd_max_reference.py 5 16 33 65  -> L, positive thresholds, rho.
import mpmath as mp, math, sys
mp.mp.dps = 40
def design(L):
    # float Lloyd iterations for a start
    t = [(-4 + 8*(i+1)/L) for i in range(L-1)]
    phi = lambda x: math.exp(-x*x/2)/math.sqrt(2*math.pi)
    Phi = lambda x: 0.5*math.erfc(-x/math.sqrt(2))
    for it in range(20000):
        edges = [-math.inf]+t+[math.inf]
        y = []
        for a,b in zip(edges[:-1],edges[1:]):
            pa = phi(a) if a!=-math.inf else 0.0; pb = phi(b) if b!=math.inf else 0.0
            y.append((pa-pb)/(Phi(b)-Phi(a)))
        t = [(y[i]+y[i+1])/2 for i in range(L-1)]
    # symmetric unknowns: positive thresholds (and 0 if L even)
    m = (L-1)//2  # number of strictly positive thresholds
    pos = sorted(x for x in t if x > 1e-9)[:m]
    def full(p):
        p = list(p)
        if L % 2 == 0:
            return [-x for x in reversed(p)] + [mp.mpf(0)] + p
        return [-x for x in reversed(p)] + p
    def means(tt):
        edges = [-mp.inf]+tt+[mp.inf]
        ys=[]; ps=[]
        for a,b in zip(edges[:-1],edges[1:]):
            pa = mp.npdf(a) if a!=-mp.inf else 0; pb = mp.npdf(b) if b!=mp.inf else 0
            pr = mp.ncdf(b)-mp.ncdf(a)
            ys.append((pa-pb)/pr); ps.append(pr)
        return ys, ps
    def eqs(*p):
        tt = full(p)
        ys,_ = means(tt)
        off = len(tt)-len(p)
        return [tt[off+i] - (ys[off+i]+ys[off+i+1])/2 for i in range(len(p))]
    sol = mp.findroot(eqs, [mp.mpf(x) for x in pos], tol=mp.mpf(10)**-35)
    sol = [sol] if m == 1 else list(sol)
    tt = full(sol)
    ys, ps = means(tt)
    rho = sum(p*y*y for p,y in zip(ps,ys))
    return sol, rho
for L in [int(a) for a in sys.argv[1:]]:
    sol, rho = design(L)
    print(L, [mp.nstr(x, 20) for x in sol], mp.nstr(rho, 20), flush=True)
