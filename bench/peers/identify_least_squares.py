#!/usr/bin/env python3
"""Peer of needle-identify: the same probing fit (equation 5) with scipy's
least_squares, on the same T6 plane-strain mesh, data rows and load points,
written by

    cargo run --release -p needle-identify --example probe_peer_export -- DIR
    python3 bench/peers/identify_least_squares.py DIR

The finite-element model is written here from scratch with numpy/scipy
(6-node triangles, 3-point Gauss rule, fixed back face eliminated, sparse LU
from scipy), so the comparison checks the Rust model as well as the
optimiser. Prints a markdown table: start, final E and nu, final cost
(1/2 sum of squared whitened residuals), residual evaluations and time,
for scipy (trust-region reflective, 2-point finite differences, bounds) next
to needle-identify's figures from DIR/ours.csv.
"""

import csv
import sys
import time

import numpy as np
import scipy.sparse as sp
import scipy.sparse.linalg as spla
from scipy.optimize import least_squares


def read(path):
    with open(path) as f:
        rows = list(csv.DictReader(f))
    return {k: np.array([float(r[k]) for r in rows]) for k in rows[0]}


def t6_shape_gradients(l0, l1, l2):
    """Gradients of the six T6 shape functions w.r.t. the reference (xi, eta),
    with L0 = 1 - xi - eta, L1 = xi, L2 = eta; corners 0,1,2 then mid-edges
    01, 12, 20 (the needle-fem order)."""
    dl = np.array([[-1.0, -1.0], [1.0, 0.0], [0.0, 1.0]])
    lam = (l0, l1, l2)
    grads = [(4.0 * lam[i] - 1.0) * dl[i] for i in range(3)]
    for a, b in ((0, 1), (1, 2), (2, 0)):
        grads.append(4.0 * (lam[a] * dl[b] + lam[b] * dl[a]))
    return np.array(grads)  # 6 x 2


GAUSS = [((2 / 3, 1 / 6, 1 / 6), 1 / 6), ((1 / 6, 2 / 3, 1 / 6), 1 / 6), ((1 / 6, 1 / 6, 2 / 3), 1 / 6)]


class Model:
    def __init__(self, folder):
        nodes = read(f"{folder}/nodes.csv")
        self.x = np.column_stack([nodes["x"], nodes["y"]])
        el = read(f"{folder}/elements.csv")
        self.elements = np.column_stack([el[f"n{i}"] for i in range(6)]).astype(int)
        setup = read(f"{folder}/setup.csv")
        self.setup = {k: v[0] for k, v in setup.items()}
        self.thickness = self.setup["thickness"]
        n = len(self.x)
        fixed_nodes = np.where(np.abs(self.x[:, 1] - self.setup["depth"]) < 1e-12)[0]
        fixed = np.zeros(2 * n, bool)
        fixed[2 * fixed_nodes] = True
        fixed[2 * fixed_nodes + 1] = True
        self.free = np.where(~fixed)[0]
        # Element B matrices at the Gauss points (geometry only).
        self.b = []
        for e in self.elements:
            xe = self.x[e]
            per_point = []
            for (l0, l1, l2), w in GAUSS:
                g = t6_shape_gradients(l0, l1, l2)  # 6x2 reference gradients
                jac = xe.T @ g  # 2x2
                det = np.linalg.det(jac)
                dn = g @ np.linalg.inv(jac)  # 6x2 physical gradients
                bm = np.zeros((3, 12))
                bm[0, 0::2] = dn[:, 0]
                bm[1, 1::2] = dn[:, 1]
                bm[2, 0::2] = dn[:, 1]
                bm[2, 1::2] = dn[:, 0]
                per_point.append((bm, w * det))
            self.b.append(per_point)
        dofs = np.column_stack([2 * self.elements, 2 * self.elements + 1]).reshape(-1, 2, 6).transpose(0, 2, 1).reshape(-1, 12)
        self.rows_idx = np.repeat(dofs, 12, axis=1).ravel()
        self.cols_idx = np.tile(dofs, (1, 12)).ravel()
        self.n = n
        # Loads: unit forces at the load points on the front face (y = 0),
        # consistent with the quadratic edge shape functions.
        frames = read(f"{folder}/frames.csv")
        self.frames = frames
        points = np.unique(np.column_stack([frames["load_x"], frames["load_y"]]), axis=0)
        self.points = points
        self.frame_point = np.array(
            [np.argmin(np.hypot(points[:, 0] - x, points[:, 1] - y)) for x, y in zip(frames["load_x"], frames["load_y"])]
        )
        front = []
        for e in self.elements:
            for a, b, m in ((0, 1, 3), (1, 2, 4), (2, 0, 5)):
                if abs(self.x[e[a], 1]) < 1e-12 and abs(self.x[e[b], 1]) < 1e-12:
                    front.append((e[a], e[b], e[m]))
        self.loads = np.zeros((2 * n, 2 * len(points)))
        for p, (px, _py) in enumerate(points):
            for a, b, m in front:
                xa, xb = self.x[a, 0], self.x[b, 0]
                lo, hi = min(xa, xb), max(xa, xb)
                if lo - 1e-12 <= px <= hi + 1e-12:
                    s = (px - xa) / (xb - xa)
                    shape = {a: (1 - s) * (1 - 2 * s), b: s * (2 * s - 1), m: 4 * s * (1 - s)}
                    for node, value in shape.items():
                        for c in range(2):
                            self.loads[2 * node + c, 2 * p + c] += value
                    break
        rows = read(f"{folder}/rows.csv")
        self.row_frame = rows["frame"].astype(int)
        self.row_dof = (2 * rows["node"] + rows["component"]).astype(int)
        self.value = rows["value"]
        self.weight = rows["weight"]
        self.evaluations = 0

    def stiffness(self, e_mod, nu):
        lam = e_mod * nu / ((1 + nu) * (1 - 2 * nu))
        mu = e_mod / (2 * (1 + nu))
        d = np.array([[lam + 2 * mu, lam, 0], [lam, lam + 2 * mu, 0], [0, 0, mu]])
        values = np.empty((len(self.elements), 144))
        for k, per_point in enumerate(self.b):
            ke = np.zeros((12, 12))
            for bm, w in per_point:
                ke += w * bm.T @ d @ bm
            values[k] = self.thickness * ke.ravel()
        k = sp.csc_matrix((values.ravel(), (self.rows_idx, self.cols_idx)), shape=(2 * self.n, 2 * self.n))
        return k[self.free][:, self.free]

    def residuals(self, params):
        self.evaluations += 1
        e_mod, nu = params
        k = self.stiffness(e_mod, nu)
        u = np.zeros_like(self.loads)
        u[self.free] = spla.splu(k.tocsc()).solve(self.loads[self.free])
        f = self.frames
        p = self.frame_point[self.row_frame]
        pred = f["fx"][self.row_frame] * u[self.row_dof, 2 * p] + f["fy"][self.row_frame] * u[self.row_dof, 2 * p + 1]
        return self.weight * (self.value - pred)


def main():
    folder = sys.argv[1] if len(sys.argv) > 1 else "/tmp/identify-peer"
    model = Model(folder)
    s = model.setup
    ours = read(f"{folder}/ours.csv")
    print("| solver | start (E Pa, nu) | E (Pa) | nu | final cost | residual evaluations | time (s) |")
    print("|---|---|---|---|---|---|---|")
    for i in range(len(ours["E"])):
        start = (ours["start_E"][i], ours["start_nu"][i])
        print(
            f"| needle-identify | ({start[0]:g}, {start[1]:g}) | {ours['E'][i]:.2f} | {ours['nu'][i]:.5f} | "
            f"{ours['cost'][i]:.2f} | {int(ours['evaluations'][i])} (+{int(ours['jacobians'][i])} analytic Jacobians) | "
            f"{ours['seconds'][i]:.2f} |"
        )
    for i in range(len(ours["E"])):
        start = np.array([ours["start_E"][i], ours["start_nu"][i]])
        model.evaluations = 0
        clock = time.perf_counter()
        result = least_squares(
            model.residuals,
            start,
            bounds=([s["E_lo"], s["nu_lo"]], [s["E_hi"], s["nu_hi"]]),
            x_scale=[max(start[0], 1.0), 0.01],
            method="trf",
        )
        seconds = time.perf_counter() - clock
        print(
            f"| scipy least_squares (trf) | ({start[0]:g}, {start[1]:g}) | {result.x[0]:.2f} | {result.x[1]:.5f} | "
            f"{result.cost:.2f} | {model.evaluations} (incl. finite differences) | {seconds:.2f} |"
        )


if __name__ == "__main__":
    main()
