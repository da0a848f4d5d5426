#!/usr/bin/python3
"""Scores a job's floor plans against a simulated building's truth rooms.

    room_score_sim.py GT/building.json OUT [OUT ...]

For each level of the truth, the rooms the walk entered (gt/building.json "entered",
docs/DESIGN.md §4) and the rooms of OUT/level_<k>/floorplan.geojson (§7) are rasterised at
10 cm; a truth room is matched when a predicted room overlaps it at IoU > 0.5 (which makes the
match one-to-one), as services/floorplan/eval/room_scoring.h scores the real maps. Prints per level
and per job: truth rooms, predicted rooms, matched, precision, recall, F1. numpy only.
"""
import collections
import json
import sys

import numpy as np

RES = 0.1
def inside(poly, X, Y):
    poly=np.asarray(poly,float); x=poly[:,0]; y=poly[:,1]
    r=np.zeros(X.shape,bool); j=len(poly)-1
    for i in range(len(poly)):
        c=((y[i]>Y)!=(y[j]>Y)) & (X < (x[j]-x[i])*(Y-y[i])/(y[j]-y[i]+1e-300)+x[i])
        r^=c; j=i
    return r
def raster(polys, lo, shape):
    lab=-np.ones(shape,int)
    ys=(np.arange(shape[0])+0.5)*RES+lo[1]; xs=(np.arange(shape[1])+0.5)*RES+lo[0]
    X,Y=np.meshgrid(xs,ys)
    for k,(outer,holes) in enumerate(polys):
        m=inside(outer,X,Y)
        for h in holes: m&=~inside(h,X,Y)
        lab[m]=k
    return lab
def truth(path):
    b=json.load(open(path)); out=collections.defaultdict(list)
    for r in b['rooms']:
        if r['entered']: out[r['level']].append((r['polygon'], r.get('holes') or []))
    return out
def pred(outdir, levels):
    out={}
    for k in levels:
        try: g=json.load(open(f'{outdir}/level_{k}/floorplan.geojson'))
        except FileNotFoundError: out[k]=[]; continue
        rs=[]
        for f in g['features']:
            p=f.get('properties',{})
            if 'area_m2' not in p: continue
            geom=f['geometry']
            polys=[geom['coordinates']] if geom['type']=='Polygon' else geom['coordinates']
            for c in polys: rs.append((c[0], c[1:]))
        out[k]=rs
    return out
T=truth(sys.argv[1])
for outdir in sys.argv[2:]:
    P=pred(outdir, T.keys()); tm=tp=tt=0
    for k in sorted(T):
        allp=[p for p,_ in T[k]]+[p for p,_ in P[k]]
        pts=np.concatenate([np.asarray(p) for p in allp])
        lo=pts.min(0)-0.5; hi=pts.max(0)+0.5
        shape=(int((hi[1]-lo[1])/RES)+1, int((hi[0]-lo[0])/RES)+1)
        lt=raster(T[k],lo,shape); lp=raster(P[k],lo,shape)
        nt=len(T[k]); npd=len(P[k])
        inter=np.zeros((nt,npd)); m=(lt>=0)&(lp>=0)
        np.add.at(inter,(lt[m],lp[m]),1)
        at=np.bincount(lt[lt>=0],minlength=nt); ap=np.bincount(lp[lp>=0],minlength=npd)
        iou=inter/(at[:,None]+ap[None,:]-inter+1e-9)
        matched=int((iou.max(1)>0.5).sum()) if npd else 0
        tm+=matched; tt+=nt; tp+=npd
        print(f'  level {k}: truth {nt}, predicted {npd}, matched at IoU>0.5: {matched}')
    print(outdir, f'matched {tm} of {tt} true, {tp} predicted: precision {tm/tp:.3f} recall {tm/tt:.3f} F1 {2*tm/(tp+tt):.3f}')
