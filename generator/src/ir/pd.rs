//! The paper's PD-approximated Euler-Lagrange model, built symbolically.
//!
//! M̄ q̈ + C̄ q̇ + Ḡ = R̄ [S1 μ − S2 q − S3 q̇ − S4 q̈ + S5]  (MODEL_NOTES.md), so
//! q̈ = (M̄ + R̄ S4)⁻¹ [R̄ (S1 μ − S2 q − S3 q̇ + S5) − C̄ q̇ − Ḡ].
//!
//! * Translation: (m I + ξ11 b e3ᵀ) η̈ = b T − m g e3 with b = R e3 and
//!   T = ξ1 u_vz − ξ7 ż + ξ13; solved in closed form (the z row first).
//! * Rotation: (M(Ω) + diag(0, 0, ξ12)) Ω̈ = τ − C(Ω, Ω̇) Ω̇, with C from
//!   Christoffel symbols of M and the symmetric 3×3 inverse by cofactors.

use crate::model::PdParams;
use crate::symbolic::{diff, Graph, Id};

/// Variable ids in state order (x y z φ θ ψ ẋ ẏ ż φ̇ θ̇ ψ̇) then inputs.
pub struct PdVars {
    pub q: [Id; 6],
    pub qd: [Id; 6],
    pub u: [Id; 4],
}

impl PdVars {
    pub fn new(v: &[Id]) -> Self {
        let q = [v[0], v[1], v[2], v[3], v[4], v[5]];
        let qd = [v[6], v[7], v[8], v[9], v[10], v[11]];
        let u = [v[12], v[13], v[14], v[15]];
        Self { q, qd, u }
    }
}

type Mat3 = [[Id; 3]; 3];

/// M(Ω) = Wᵀ diag(Ix, Iy, Iz) W, W = [[1, 0, −sθ], [0, cφ, sφ cθ], [0, −sφ, cφ cθ]].
pub fn inertia(g: &mut Graph, v: &PdVars, p: &PdParams) -> Mat3 {
    let (phi, theta) = (v.q[3], v.q[4]);
    let (sphi, cphi) = (g.sin(phi), g.cos(phi));
    let (stheta, ctheta) = (g.sin(theta), g.cos(theta));
    let zero = g.zero();
    let one = g.one();
    let mstheta = g.neg(stheta);
    let msphi = g.neg(sphi);
    let sphictheta = g.mul(sphi, ctheta);
    let cphictheta = g.mul(cphi, ctheta);
    let w: Mat3 = [
        [one, zero, mstheta],
        [zero, cphi, sphictheta],
        [zero, msphi, cphictheta],
    ];
    let inertia = [p.xi(14), p.xi(15), p.xi(16)].map(|i| g.constant(i));
    let mut m = [[zero; 3]; 3];
    for i in 0..3 {
        for j in 0..3 {
            // M_ij = Σ_k W_ki I_k W_kj
            let terms: Vec<Id> = (0..3)
                .map(|k| {
                    let a = g.mul(w[k][i], inertia[k]);
                    g.mul(a, w[k][j])
                })
                .collect();
            m[i][j] = g.sum(terms);
        }
    }
    m
}

/// C_ij = Σ_k ½ (∂M_ij/∂Ω_k + ∂M_ik/∂Ω_j − ∂M_jk/∂Ω_i) Ω̇_k  (Christoffel symbols of the first kind).
pub fn coriolis(g: &mut Graph, v: &PdVars, m: &Mat3) -> Mat3 {
    let angle_vars = [3usize, 4, 5];
    let zero = g.zero();
    let mut dm = [[[zero; 3]; 3]; 3]; // dm[k][i][j] = ∂M_ij/∂Ω_k
    for (k, &var) in angle_vars.iter().enumerate() {
        for i in 0..3 {
            for j in 0..3 {
                dm[k][i][j] = diff(g, m[i][j], var);
            }
        }
    }
    let half = g.constant(0.5);
    let mut c = [[zero; 3]; 3];
    for i in 0..3 {
        for j in 0..3 {
            let terms: Vec<Id> = (0..3)
                .map(|k| {
                    let s = g.add(dm[k][i][j], dm[j][i][k]);
                    let gamma = g.sub(s, dm[i][j][k]);
                    let hg = g.mul(half, gamma);
                    g.mul(hg, v.qd[3 + k])
                })
                .collect();
            c[i][j] = g.sum(terms);
        }
    }
    c
}

/// ẋ = f(x, u) for the PD model: [q̇, q̈].
pub fn dynamics(g: &mut Graph, vars: &[Id], p: &PdParams) -> Vec<Id> {
    let v = PdVars::new(vars);
    let xi = |g: &mut Graph, k: usize| g.constant(p.xi(k));
    let (phi, theta, psi) = (v.q[3], v.q[4], v.q[5]);
    let (sphi, cphi) = (g.sin(phi), g.cos(phi));
    let (stheta, ctheta) = (g.sin(theta), g.cos(theta));
    let (spsi, cpsi) = (g.sin(psi), g.cos(psi));

    // b = R e3 = [cψ sθ cφ + sψ sφ, sψ sθ cφ − cψ sφ, cθ cφ]
    let stcp = g.mul(stheta, cphi);
    let a = g.mul(cpsi, stcp);
    let bb = g.mul(spsi, sphi);
    let bx = g.add(a, bb);
    let a = g.mul(spsi, stcp);
    let bb = g.mul(cpsi, sphi);
    let by = g.sub(a, bb);
    let bz = g.mul(ctheta, cphi);

    // T = ξ1 u_vz − ξ7 ż + ξ13
    let x1 = xi(g, 1);
    let x7 = xi(g, 7);
    let x13 = xi(g, 13);
    let a = g.mul(x1, v.u[0]);
    let bb = g.mul(x7, v.qd[2]);
    let a = g.sub(a, bb);
    let thrust = g.add(a, x13);

    // z̈ = (b_z T − m g) / (m + ξ11 b_z)
    let m = g.constant(p.mass);
    let mg = g.constant(p.mass * p.gravity);
    let x11 = xi(g, 11);
    let num = g.mul(bz, thrust);
    let num = g.sub(num, mg);
    let den = g.mul(x11, bz);
    let den = g.add(m, den);
    let zdd = g.div(num, den);
    // ẍ, ÿ = b_{x,y} (T − ξ11 z̈) / m
    let t = g.mul(x11, zdd);
    let t = g.sub(thrust, t);
    let inv_m = g.constant(1.0 / p.mass);
    let t = g.mul(t, inv_m);
    let xdd = g.mul(bx, t);
    let ydd = g.mul(by, t);

    // τ = [ξ2 u_φ − ξ5 φ − ξ8 φ̇, ξ3 u_θ − ξ6 θ − ξ9 θ̇, ξ4 u_ψ̇ − ξ10 ψ̇]
    let mut tau = [g.zero(); 3];
    for (r, (gain, stiff, damp)) in [(2, Some(5), 8), (3, Some(6), 9), (4, None, 10)]
        .into_iter()
        .enumerate()
    {
        let k = xi(g, gain);
        let mut e = g.mul(k, v.u[1 + r]);
        if let Some(s) = stiff {
            let ks = xi(g, s);
            let t = g.mul(ks, v.q[3 + r]);
            e = g.sub(e, t);
        }
        let kd = xi(g, damp);
        let t = g.mul(kd, v.qd[3 + r]);
        tau[r] = g.sub(e, t);
    }

    // rhs = τ − C Ω̇
    let mm = inertia(g, &v, p);
    let c = coriolis(g, &v, &mm);
    let mut rhs = [g.zero(); 3];
    for i in 0..3 {
        let terms: Vec<Id> = (0..3).map(|j| g.mul(c[i][j], v.qd[3 + j])).collect();
        let cq = g.sum(terms);
        rhs[i] = g.sub(tau[i], cq);
    }
    // A = M + diag(0, 0, ξ12); Ω̈ = A⁻¹ rhs = adj(A) rhs / det A
    let mut am = mm;
    let x12 = xi(g, 12);
    am[2][2] = g.add(am[2][2], x12);
    let omega_dd = solve_sym3(g, &am, &rhs);

    vec![
        v.qd[0],
        v.qd[1],
        v.qd[2],
        v.qd[3],
        v.qd[4],
        v.qd[5],
        xdd,
        ydd,
        zdd,
        omega_dd[0],
        omega_dd[1],
        omega_dd[2],
    ]
}

/// x = A⁻¹ b for symmetric 3×3 A by cofactors: x = adj(A) b / det A.
fn solve_sym3(g: &mut Graph, a: &Mat3, b: &[Id; 3]) -> [Id; 3] {
    let cof = |g: &mut Graph, r0: usize, r1: usize, c0: usize, c1: usize| {
        let p = g.mul(a[r0][c0], a[r1][c1]);
        let q = g.mul(a[r0][c1], a[r1][c0]);
        g.sub(p, q)
    };
    // adj(A) is symmetric for symmetric A.
    let c00 = cof(g, 1, 2, 1, 2);
    let c01 = cof(g, 0, 2, 2, 1); // −(a01 a22 − a02 a21) = a02 a21 − a01 a22
    let c02 = cof(g, 0, 1, 1, 2);
    let c11 = cof(g, 0, 2, 0, 2);
    let c12 = cof(g, 0, 1, 2, 0); // −(a00 a12 − a02 a10)
    let c22 = cof(g, 0, 1, 0, 1);
    let adj = [[c00, c01, c02], [c01, c11, c12], [c02, c12, c22]];
    let terms: Vec<Id> = (0..3).map(|k| g.mul(a[0][k], adj[k][0])).collect();
    let det = g.sum(terms);
    let inv_det = g.recip(det);
    let mut x = [g.zero(); 3];
    for i in 0..3 {
        let terms: Vec<Id> = (0..3).map(|j| g.mul(adj[i][j], b[j])).collect();
        let s = g.sum(terms);
        x[i] = g.mul(s, inv_det);
    }
    x
}
