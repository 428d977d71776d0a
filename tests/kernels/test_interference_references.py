"""Segment distances against two independent implementations: Drake's SceneGraph capsule
signed distance and python-fcl's capsule distance (distance = capsule distance + 2 radius)."""

import numpy as np
import pytest

from cdpm_drake.kernels.interference import segment_distance

RADIUS = 1e-3  # m; any radius works as long as the capsules do not overlap much


def random_segment_pairs(seed, n):
    """Random cable pairs of a few metres, as in a CDPM: (n, 4, 3) rows B_i, A_i, B_j, A_j."""
    rng = np.random.default_rng(seed)
    return rng.normal(scale=1.5, size=(n, 4, 3))


def capsule_pose(P, Q):
    """Pose of a capsule (axis along its z) spanning the segment P-Q, and its length."""
    from pydrake.math import RigidTransform, RotationMatrix

    d = Q - P
    length = float(np.linalg.norm(d))
    return RigidTransform(RotationMatrix.MakeFromOneVector(d / length, 2), 0.5 * (P + Q)), length


def test_segment_distance_matches_drake_scene_graph_capsules():
    from pydrake.geometry import (Capsule, FramePoseVector, GeometryFrame, GeometryInstance,
                                  ProximityProperties, SceneGraph)
    from pydrake.math import RigidTransform

    cases = random_segment_pairs(11, 40)
    sg = SceneGraph()
    source = sg.RegisterSource("cables")
    frames, ids = [], []
    for k, case in enumerate(cases):
        pair = []
        for m, (P, Q) in enumerate((case[:2], case[2:])):
            frame = sg.RegisterFrame(source, GeometryFrame(f"cable_{k}_{m}"))
            X_FG, length = capsule_pose(P, Q)
            g = sg.RegisterGeometry(source, frame,
                                    GeometryInstance(X_FG, Capsule(RADIUS, length), f"c{k}_{m}"))
            sg.AssignRole(source, g, ProximityProperties())
            frames.append(frame)
            pair.append(g)
        ids.append(pair)
    context = sg.CreateDefaultContext()
    poses = FramePoseVector()
    for frame in frames:
        poses.set_value(frame, RigidTransform())
    sg.get_source_pose_port(source).FixValue(context, poses)
    query = sg.get_query_output_port().Eval(context)
    for case, (ga, gb) in zip(cases, ids):
        ref = query.ComputeSignedDistancePairClosestPoints(ga, gb).distance + 2 * RADIUS
        # Drake's capsule-capsule distance goes through FCL's GJK with a 1e-6 tolerance (the
        # largest gap seen over these cases is 3e-6 m), hence the tolerance here; the exact
        # rational reference in test_interference.py is the tight check.
        assert segment_distance(*case).distance == pytest.approx(ref, abs=1e-5)


def test_segment_distance_matches_fcl_capsules():
    fcl = pytest.importorskip("fcl", reason="python-fcl is optional (pip install -e .[bench])")

    for case in random_segment_pairs(12, 200):
        objs = []
        for P, Q in (case[:2], case[2:]):
            X, length = capsule_pose(P, Q)
            objs.append(fcl.CollisionObject(fcl.Capsule(RADIUS, length),
                                            fcl.Transform(X.rotation().matrix(),
                                                          X.translation())))
        ref = fcl.distance(objs[0], objs[1], fcl.DistanceRequest(), fcl.DistanceResult())
        # FCL's capsule-capsule distance is analytic: agreement to round-off.
        assert segment_distance(*case).distance == pytest.approx(ref + 2 * RADIUS, abs=1e-12)
