#!/usr/bin/env python3
"""Peer for needle-fem: the plane-strain T6 problem of
crates/fem/examples/peer_problem.rs, built and solved with scikit-fem and
SciPy (plus CHOLMOD and MKL PARDISO when they are installed), printing the
same table: medians in seconds per phase.

Install and run:
    python3 -m pip install scikit-fem scipy numpy
    # optional, the peer's best solvers (each is reported if importable):
    python3 -m pip install pypardiso           # MKL PARDISO
    apt-get install libsuitesparse-dev libopenblas0-pthread
    python3 -m pip install "scikit-sparse==0.4.16"   # CHOLMOD (0.4.x for SuiteSparse 5)
    python3 bench/peers/fem_skfem_peer.py            # n = 35, 111, 353
    python3 bench/peers/fem_skfem_peer.py 35 111     # other cell counts
    python3 bench/peers/fem_skfem_peer.py 353 --repeats=1

Our side:
    cargo run --release -p needle-fem --example peer_problem

The problem: 75 mm x 75 mm, 7.5 mm thick, plane strain, E = 25.3 kPa,
nu = 0.48, back face y = 75 mm fixed, 1 kPa traction in -y on the front face
y = 0. The mesh is the same as RectangleMesh::uniform(n, n): each grid cell
(i, j) is cut along the diagonal (i, j)-(i+1, j+1) when i + j is even and
(i+1, j)-(i, j+1) otherwise (skfem's MeshTri.init_tensor has a single
diagonal direction, so the triangles are built explicitly), then P2.

Phases (mesh generation is timed but not in the total, as on our side):
    assemble  Basis (dofs, mapping, quadrature), K = asm(linear_elasticity)
              in CSR, and the traction vector (FacetBasis + LinearForm)
    condense  skfem.condense: K_II and f_I for the free dofs
    symbolic  ordering + symbolic analysis (CHOLMOD analyze, PARDISO phase
              11); '-' for SuperLU, which cannot separate it
    numeric   numeric factorisation (SuperLU: splu, symbolic included;
              CHOLMOD cholesky_inplace; PARDISO phase 22)
    solve     the triangular solves and the expansion to all dofs
    total     assemble + condense + symbolic + numeric + solve
K is assembled once per repeat and shared by the solvers. mean_uy is the
arithmetic mean of u_y over all nodes (corner and mid-side) on the front
face; peak_MB is the process's peak resident memory so far (ru_maxrss).
"""
import resource
import sys
import time

import numpy as np
import scipy.sparse as sp
from scipy.sparse.linalg import splu
from skfem import (Basis, ElementTriP2, ElementVector, FacetBasis, LinearForm,
                   MeshTri, asm, condense)
from skfem.models.elasticity import lame_parameters, linear_elasticity

SIDE = 0.075
THICKNESS = 0.0075
YOUNGS_MODULUS = 25.3e3
POISSON_RATIO = 0.48
TRACTION = 1.0e3

HEADER = ("solver               cells     dofs    nnz(K)     nnz(L) rep    mesh assemble "
          "condense symbolic  numeric    solve    total        mean_uy  peak_MB")


def build_mesh(n):
    """The n x n checkerboard-diagonal triangulation of the square."""
    line = np.linspace(0.0, SIDE, n + 1)
    x, y = np.meshgrid(line, line)  # node j * (n + 1) + i is (x_i, y_j)
    points = np.vstack([x.ravel(), y.ravel()])
    i, j = (g.ravel() for g in np.meshgrid(np.arange(n), np.arange(n)))
    a = j * (n + 1) + i
    b, c, d = a + 1, a + n + 2, a + n + 1
    even = (i + j) % 2 == 0
    first = np.where(even, [a, b, c], [a, b, d])
    second = np.where(even, [a, c, d], [b, c, d])
    return MeshTri(points, np.hstack([first, second]))


@LinearForm
def front_traction(v, w):
    return -TRACTION * v.value[1]


def assemble(mesh):
    element = ElementVector(ElementTriP2())
    # Degree-2 rules integrate the P2 stiffness and the P2 edge load exactly.
    basis = Basis(mesh, element, intorder=2)
    lam, mu = lame_parameters(YOUNGS_MODULUS, POISSON_RATIO)  # plane strain
    stiffness = THICKNESS * asm(linear_elasticity(lam, mu), basis)
    front = mesh.facets_satisfying(lambda x: np.isclose(x[1], 0.0))
    facet_basis = FacetBasis(mesh, element, facets=front, intorder=4)
    loads = THICKNESS * asm(front_traction, facet_basis)
    return basis, stiffness.tocsr(), loads


class SuperLU:
    name = "skfem/SuperLU"

    def symbolic(self, a):
        return None

    def numeric(self, a):
        # Symmetric mode with a minimum-degree ordering of A^T + A and no
        # pivoting: SuperLU's best settings for an SPD matrix.
        self.lu = splu(a.tocsc(), permc_spec="MMD_AT_PLUS_A", diag_pivot_thresh=0.0,
                       options=dict(SymmetricMode=True))

    def factor_nnz(self):
        return self.lu.L.nnz

    def solve(self, b):
        return self.lu.solve(b)

    def release(self):
        del self.lu


class Cholmod:
    name = "skfem/CHOLMOD"

    def __init__(self):
        from sksparse.cholmod import analyze
        self.analyze = analyze

    def symbolic(self, a):
        self.a = a.tocsc()
        self.factor = self.analyze(self.a)
        return True

    def numeric(self, a):
        self.factor.cholesky_inplace(self.a)

    def factor_nnz(self):
        return self.factor.L().nnz

    def solve(self, b):
        return self.factor(b)

    def release(self):
        del self.factor, self.a


class Pardiso:
    name = "skfem/PARDISO"

    def __init__(self):
        import pypardiso
        self.make = lambda: pypardiso.PyPardisoSolver(mtype=2)  # real SPD
        self.solver = None

    def symbolic(self, a):
        # A fresh solver per matrix, so that iparm reports this factor.
        self.solver = self.make()
        # PARDISO's SPD mode reads the upper triangle in CSR.
        self.upper = sp.triu(a, format="csr")
        self.upper.sort_indices()
        self.solver._check_A(self.upper)
        self.rhs = np.zeros((a.shape[0], 1))
        self.solver.set_phase(11)
        self.solver._call_pardiso(self.upper, self.rhs)
        return True

    def numeric(self, a):
        self.solver.set_phase(22)
        self.solver._call_pardiso(self.upper, self.rhs)

    def factor_nnz(self):
        return int(self.solver.get_iparm(18))  # nonzeros in the factor

    def solve(self, b):
        self.solver.set_phase(33)
        return self.solver._call_pardiso(self.upper, np.asarray(b, dtype=float).reshape(-1, 1))[:, 0]

    def release(self):
        self.solver.free_memory(everything=True)
        self.solver = None


def available_solvers():
    solvers = [SuperLU()]
    for make in (Cholmod, Pardiso):
        try:
            solvers.append(make())
        except (ImportError, OSError) as error:
            print(f"# {make.name} not available: {error}", file=sys.stderr)
    return solvers


def peak_megabytes():
    return resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024.0


def run(n, solvers):
    """One repeat: mesh, assembly, condensation, then each solver."""
    start = time.perf_counter()
    mesh = build_mesh(n)
    mesh_time = time.perf_counter() - start

    start = time.perf_counter()
    basis, stiffness, loads = assemble(mesh)
    assemble_time = time.perf_counter() - start

    start = time.perf_counter()
    fixed = basis.get_dofs(lambda x: np.isclose(x[1], SIDE)).all()
    reduced, rhs, u, free = condense(stiffness, loads, D=fixed, expand=True)
    condense_time = time.perf_counter() - start

    front = basis.get_dofs(lambda x: np.isclose(x[1], 0.0)).all("u^2")
    results = {}
    for solver in solvers:
        start = time.perf_counter()
        has_symbolic = solver.symbolic(reduced) is not None
        symbolic_time = time.perf_counter() - start
        start = time.perf_counter()
        solver.numeric(reduced)
        numeric_time = time.perf_counter() - start
        start = time.perf_counter()
        x = u.copy()
        x[free] = solver.solve(rhs)
        solve_time = time.perf_counter() - start
        factor_nnz = solver.factor_nnz()
        # Keep one factor in memory at a time.
        solver.release()
        results[solver.name] = dict(
            dofs=basis.N, nnz=stiffness.nnz, factor_nnz=factor_nnz,
            mesh=mesh_time, assemble=assemble_time, condense=condense_time,
            symbolic=symbolic_time if has_symbolic else None, numeric=numeric_time,
            solve=solve_time,
            total=assemble_time + condense_time + symbolic_time + numeric_time + solve_time,
            mean_uy=float(np.mean(x[front])), front_nodes=len(front))
    return results


def main():
    # "--repeats=N" overrides the number of repeats (5, or 3 from 300 cells).
    options = [a for a in sys.argv[1:] if a.startswith("--repeats=")]
    forced = int(options[-1].split("=")[1]) if options else None
    cells = [int(a) for a in sys.argv[1:] if not a.startswith("--")] or [35, 111, 353]
    solvers = available_solvers()
    print("scikit-fem peer; medians in s; K assembled once per repeat and shared by the solvers")
    print(HEADER)
    for n in cells:
        repeats = forced or (3 if n >= 300 else 5)
        runs = [run(n, solvers) for _ in range(repeats)]
        for solver in solvers:
            rows = [r[solver.name] for r in runs]
            first = rows[0]
            if first["front_nodes"] != 2 * n + 1:
                raise RuntimeError(f"{first['front_nodes']} front nodes, expected {2 * n + 1}")

            def med(key):
                values = [r[key] for r in rows]
                return "       -" if values[0] is None else f"{float(np.median(values)):>8.3f}"

            print(f"{solver.name:<20} {n:>5} {first['dofs']:>8} {first['nnz']:>9} "
                  f"{first['factor_nnz']:>10} {repeats:>3} {med('mesh'):>7} {med('assemble')} "
                  f"{med('condense')} {med('symbolic')} {med('numeric')} {med('solve')} "
                  f"{med('total')} {first['mean_uy']:>14.8e} {peak_megabytes():>8.0f}",
                  flush=True)


if __name__ == "__main__":
    main()
