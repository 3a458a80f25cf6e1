#!/usr/bin/env python3
"""The reference numbers of tests/rigid_contact.rs: the initial stiffness of
the biaxial specimen (theory §8.1) under a rough rigid platen, by a bilinear
plane-strain finite-element model independent of mpm-geo.

    python3 scripts/rough_top_fe.py          # h = 1/300, 1/500, 1/700, 1/1000 m
    python3 scripts/rough_top_fe.py 300 1000 # chosen meshes (cells per metre)

The model: the quarter specimen x ∈ [0, 0.03], y ∈ [0, 0.05] m on square Q4
cells of side h = 1/n m, 2 × 2 Gauss points, linear elastic plane strain
(E = 20,000 kPa, ν = 0.2, theory §8.1's Table 1); rollers on the symmetry
lines (u_x = 0 on x = 0, u_y = 0 on y = 0); the top nodes tied to the platen
(u_x = 0) and pushed down together by δ. The lateral pressure does not enter
the stiffness (the model is linear). Prints F/δ, kN/m per m, where F is the
sum of the top nodes' vertical reactions. Homogeneous plane strain with
smooth platens would give E/(1 − ν²) w/H = 12,500.

Standard library only: the system is solved by a banded Cholesky
factorisation (half-bandwidth 2(nx + 2) + 1 with the nodes numbered row by
row), a few seconds for the four meshes.
"""
import math
import sys

E, NU = 20_000.0, 0.2
WIDTH, HEIGHT = 0.03, 0.05


def elasticity():
    """Plane-strain D (Voigt xx, yy, xy with engineering shear), kPa."""
    f = E / ((1.0 + NU) * (1.0 - 2.0 * NU))
    return [[f * (1.0 - NU), f * NU, 0.0],
            [f * NU, f * (1.0 - NU), 0.0],
            [0.0, 0.0, f * (1.0 - 2.0 * NU) / 2.0]]


def element_stiffness(h):
    """8 × 8 stiffness of a square Q4 of side h (unit thickness), 2 × 2 Gauss;
    local nodes (0, 0), (h, 0), (h, h), (0, h), dofs [u_x0, u_y0, u_x1, ...]."""
    d = elasticity()
    corners = [(-1, -1), (1, -1), (1, 1), (-1, 1)]
    g = 1.0 / math.sqrt(3.0)
    k = [[0.0] * 8 for _ in range(8)]
    jacobian = (h / 2.0) ** 2
    for xi in (-g, g):
        for eta in (-g, g):
            b = [[0.0] * 8 for _ in range(3)]
            for a, (xa, ya) in enumerate(corners):
                dx = xa * (1.0 + ya * eta) / 4.0 * 2.0 / h
                dy = ya * (1.0 + xa * xi) / 4.0 * 2.0 / h
                b[0][2 * a], b[1][2 * a + 1] = dx, dy
                b[2][2 * a], b[2][2 * a + 1] = dy, dx
            db = [[sum(d[r][s] * b[s][c] for s in range(3)) for c in range(8)] for r in range(3)]
            for i in range(8):
                for j in range(8):
                    k[i][j] += jacobian * sum(b[r][i] * db[r][j] for r in range(3))
    return k


def assemble(nx, ny, h):
    """Upper band of K (band[i][m] = K[i][i + m]) and the element dof lists."""
    ke = element_stiffness(h)
    node = lambda i, j: j * (nx + 1) + i
    n = 2 * (nx + 1) * (ny + 1)
    width = 2 * (nx + 2) + 2
    band = [[0.0] * width for _ in range(n)]
    elements = []
    for j in range(ny):
        for i in range(nx):
            nodes = [node(i, j), node(i + 1, j), node(i + 1, j + 1), node(i, j + 1)]
            dofs = [2 * a + c for a in nodes for c in (0, 1)]
            elements.append(dofs)
            for r, dr in enumerate(dofs):
                for c, dc in enumerate(dofs):
                    if dc >= dr:
                        band[dr][dc - dr] += ke[r][c]
    return band, elements, ke


def prescribe(band, rhs, dof, value):
    """Impose u[dof] = value symmetrically: the column moves to the right-hand side."""
    width = len(band[0])
    for m in range(1, width):
        if dof - m >= 0:
            rhs[dof - m] -= band[dof - m][m] * value
            band[dof - m][m] = 0.0
        if dof + m < len(band):
            rhs[dof + m] -= band[dof][m] * value
            band[dof][m] = 0.0
    band[dof][0], rhs[dof] = 1.0, value


def banded_cholesky_solve(band, rhs):
    """Solve K u = rhs for symmetric positive definite K in upper band storage."""
    n, width = len(band), len(band[0])
    u = [row[:] for row in band]  # u[i][m] = U(i, i + m), K = Uᵀ U
    for i in range(n):
        lo = max(0, i - width + 1)
        for m in range(width):
            j = i + m
            if j >= n:
                break
            s = u[i][m]
            for k in range(max(lo, j - width + 1), i):
                s -= u[k][i - k] * u[k][j - k]
            if m == 0:
                u[i][0] = math.sqrt(s)
            else:
                u[i][m] = s / u[i][0]
    y = rhs[:]
    for i in range(n):
        for k in range(max(0, i - width + 1), i):
            y[i] -= u[k][i - k] * y[k]
        y[i] /= u[i][0]
    for i in reversed(range(n)):
        for m in range(1, min(width, n - i)):
            y[i] -= u[i][m] * y[i + m]
        y[i] /= u[i][0]
    return y


def rough_top_stiffness(cells_per_metre):
    """F/δ (kN/m per m) of the quarter specimen with the top nodes tied."""
    h = 1.0 / cells_per_metre
    nx, ny = round(WIDTH / h), round(HEIGHT / h)
    band, elements, ke = assemble(nx, ny, h)
    rhs = [0.0] * len(band)
    delta = 1.0
    top = [ny * (nx + 1) + i for i in range(nx + 1)]
    for j in range(ny + 1):
        prescribe(band, rhs, 2 * j * (nx + 1), 0.0)  # x = 0
    for i in range(nx + 1):
        prescribe(band, rhs, 2 * i + 1, 0.0)  # y = 0
    for a in top:
        prescribe(band, rhs, 2 * a, 0.0)
        prescribe(band, rhs, 2 * a + 1, -delta)
    u = banded_cholesky_solve(band, rhs)
    reaction = [0.0] * len(u)
    for dofs in elements:
        for r, dr in enumerate(dofs):
            reaction[dr] += sum(ke[r][c] * u[dc] for c, dc in enumerate(dofs))
    return -sum(reaction[2 * a + 1] for a in top) / delta


def main():
    meshes = [int(a) for a in sys.argv[1:]] or [300, 500, 700, 1000]
    print(f"homogeneous, smooth platens: {E / (1 - NU ** 2) * WIDTH / HEIGHT:,.1f} kN/m per m")
    for n in meshes:
        print(f"h = 1/{n} m: {rough_top_stiffness(n):,.1f} kN/m per m (rough top)")


if __name__ == "__main__":
    main()
