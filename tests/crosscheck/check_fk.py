import os, json, numpy as np, sys
sys.path.insert(0, os.path.dirname(os.path.abspath(__file__)))
from sim import *
for ds in ['er3a_compliance_j2','ur5_geometric']:
    tr=json.load(open(f'{SRC}/{ds}/truth.json'))
    rows=[l.strip().split(',') for l in open(f'{SRC}/{ds}/poses.csv')][1:]
    R=rpy_to_R(tr['base_in_rig']['rpy_deg']); x=np.array(tr['base_in_rig']['xyz_mm'])
    A=np.array(tr['anchors_mm'])
    errs=[];lerr=[]
    for k,row in enumerate(rows):
        q=np.array([float(v) for v in row[1:7]])
        if tr['effects']:
            tau=gravity_torques(json.load(open(f'{SRC}/{ds}/robot.json'))['joints'],tr['true_robot']['links'],tr['true_robot']['gravity_in_base'],q)
            q[1]+=tr['effects'][0]['magnitude']*tau[1]
        p=R@tool_in_base(tr['true_robot']['joints'],tr['tool_point_mm'],q)+x
        errs.append(np.linalg.norm(p-np.array(tr['true_points_mm'][k])))
        l=np.linalg.norm(p-A,axis=1)-tr['r_mm']
        lerr.append(l-np.array([float(v) for v in row[7:11]]))
    print(ds, np.max(errs), np.sqrt(np.mean(np.square(lerr))))
