/* ncgen_condense.h: the SQP controller's condensed QP (ncgen.control.mpc) from the blocks of
 * mpc_qp_blocks, in dense loops: the one implementation of the condensing, for the exported
 * package, nc.MPC(loop="c") and nc.MPC's Python loop.  Included by <name>_mpc.c after it defines
 * NCGEN_MPC_NX, NCGEN_MPC_NU, NCGEN_MPC_N (states, inputs, intervals) and NXS, NUS.
 *
 * Arrays are column-major.  The blocks, side by side: A_k (NX x NX) and B_k (NX x NU) of the
 * step's Jacobians for k < N; d (NX x (N + 1)): d_0 = x - X_0, d_{k+1} = the shooting gap of
 * interval k; the cost's Gauss-Newton blocks Q_k (NX x NX, k <= N), M_k (NX x NU), R_k (NU x NU)
 * and gradients g_x (NX x (N + 1)), g_u (NU x N).  With dX = S dU + s (node k's rows S_k, s_k:
 * s_0 = d_0, S_0 = 0, S_{k+1} = A_k S_k + B_k E_k, s_{k+1} = A_k s_k + d_{k+1}, E_k picking
 * interval k's inputs), the condensed Hessian and gradient are
 *     H = sum_k S_k' Q_k S_k + S_k' M_k E_k + E_k' M_k' S_k + E_k' R_k E_k,
 *     g = sum_k S_k' (Q_k s_k + g_x,k) + E_k' (M_k' s_k + g_u,k).
 * S_k has nonzero columns only for the inputs before node k, which the loops skip. */

typedef struct {
    const casadi_real *A, *B, *d, *Q, *M, *R, *g_x, *g_u;
} ncgen_qp_blocks;

/* y = A x (A: NX x NX, x, y: NX values, y not x), four columns of A at a time. */
static void ncgen_condense_mv(const casadi_real* restrict A, const casadi_real* restrict x, casadi_real* restrict y) {
    int i, j;
    for (i = 0; i < NCGEN_MPC_NX; ++i) y[i] = 0.0;
    for (j = 0; j + 4 <= NCGEN_MPC_NX; j += 4) {
        const casadi_real *a0 = A + j * NCGEN_MPC_NX, *a1 = a0 + NCGEN_MPC_NX, *a2 = a1 + NCGEN_MPC_NX,
                          *a3 = a2 + NCGEN_MPC_NX, x0 = x[j], x1 = x[j + 1], x2 = x[j + 2], x3 = x[j + 3];
        for (i = 0; i < NCGEN_MPC_NX; ++i) y[i] += a0[i] * x0 + a1[i] * x1 + a2[i] * x2 + a3[i] * x3;
    }
#if NCGEN_MPC_NX % 4
    for (; j < NCGEN_MPC_NX; ++j)
        for (i = 0; i < NCGEN_MPC_NX; ++i) y[i] += A[i + j * NCGEN_MPC_NX] * x[j];
#endif
}

/* y = Q x for Q given by its n nonzero entries (rows r, columns c, values v). */
static void ncgen_condense_spmv(int n, const int* r, const int* c, const casadi_real* v, const casadi_real* x,
                                casadi_real* restrict y) {
    int i;
    for (i = 0; i < NCGEN_MPC_NX; ++i) y[i] = 0.0;
    for (i = 0; i < n; ++i) y[r[i]] += v[i] * x[c[i]];
}

static inline casadi_real ncgen_condense_dot(const casadi_real* restrict a, const casadi_real* restrict b) {
    casadi_real r = 0.0;
    int i;
    for (i = 0; i < NCGEN_MPC_NX; ++i) r += a[i] * b[i];
    return r;
}

/* S (NXS x NUS), s (NXS), H (NUS x NUS, symmetric), g (NUS) of the blocks b; T: NX x NUS work. */
static void ncgen_condense(const ncgen_qp_blocks* b, casadi_real* S, casadi_real* s, casadi_real* H,
                           casadi_real* g, casadi_real* T) {
    const int nx = NCGEN_MPC_NX, nu = NCGEN_MPC_NU;
    casadi_real q[NCGEN_MPC_NX], v[NCGEN_MPC_NX * NCGEN_MPC_NX];   /* Q_k's nonzero entries: v at rows r, columns cs */
    int r[NCGEN_MPC_NX * NCGEN_MPC_NX], cs[NCGEN_MPC_NX * NCGEN_MPC_NX];
    int i, j, k, c, c2, n;
    for (i = 0; i < NXS * NUS; ++i) S[i] = 0.0;
    for (i = 0; i < NUS * NUS; ++i) H[i] = 0.0;
    for (i = 0; i < nx; ++i) s[i] = b->d[i];
    for (k = 0; k < NCGEN_MPC_N; ++k) {
        const casadi_real* A_k = b->A + k * nx * nx;
        for (c = 0; c < k * nu; ++c) ncgen_condense_mv(A_k, S + c * NXS + k * nx, S + c * NXS + (k + 1) * nx);
        for (j = 0; j < nu; ++j)
            for (i = 0; i < nx; ++i) S[(k * nu + j) * NXS + (k + 1) * nx + i] = b->B[(k * nu + j) * nx + i];
        ncgen_condense_mv(A_k, s + k * nx, s + (k + 1) * nx);
        for (i = 0; i < nx; ++i) s[(k + 1) * nx + i] += b->d[(k + 1) * nx + i];
    }
    for (c = 0; c < NUS; ++c) g[c] = b->g_u[c];
    for (k = 0; k <= NCGEN_MPC_N; ++k) {
        const casadi_real *Q_k = b->Q + k * nx * nx, *s_k = s + k * nx;
        for (j = 0, n = 0; j < nx; ++j)                  /* the cost's Hessian is sparse (a diagonal, often) */
            for (i = 0; i < nx; ++i)
                if (Q_k[i + j * nx] != 0.0) {
                    r[n] = i;
                    cs[n] = j;
                    v[n++] = Q_k[i + j * nx];
                }
        ncgen_condense_spmv(n, r, cs, v, s_k, q);
        for (i = 0; i < nx; ++i) q[i] += b->g_x[k * nx + i];
        for (c = 0; c < k * nu; ++c) {                  /* the nonzero columns of S_k */
            const casadi_real* S_kc = S + c * NXS + k * nx;
            ncgen_condense_spmv(n, r, cs, v, S_kc, T + c * nx);
            for (c2 = 0; c2 <= c; ++c2) H[c + c2 * NUS] += ncgen_condense_dot(S_kc, T + c2 * nx);   /* lower */
            g[c] += ncgen_condense_dot(S_kc, q);
        }
        if (k == NCGEN_MPC_N) break;
        for (j = 0; j < nu; ++j) {                      /* E_k' M_k' S_k (below the diagonal), E_k' R_k E_k */
            const casadi_real* M_kj = b->M + (k * nu + j) * nx;
            const int col = k * nu + j;
            for (c = 0; c < k * nu; ++c) H[col + c * NUS] += ncgen_condense_dot(M_kj, S + c * NXS + k * nx);
            g[col] += ncgen_condense_dot(M_kj, s_k);
            for (i = j; i < nu; ++i) H[k * nu + i + col * NUS] += b->R[(k * nu + j) * nu + i];
        }
    }
    for (c2 = 0; c2 < NUS; ++c2)
        for (c = c2 + 1; c < NUS; ++c) H[c2 + c * NUS] = H[c + c2 * NUS];
}

#ifdef NCGEN_MPC_PULLS
/* The cables' rows of the QP (the path constraint P >= T_min linearised, ncgen.control.mpc_problem),
 * defined where the package defines NCGEN_MPC_PULLS (np, the pulls per interval, > 0):
 * for interval k its np pulls P_k (np x N: column k), their Jacobians P_a,k, P_b,k in x_k, x_{k+1}
 * (np x NX blocks side by side) and P_u,k in u_k (np x NU blocks), on the condensed prediction
 * dx_j = S_j dU + s_j (ncgen_condense's S, s):
 *     A_k = P_a,k S_k + P_b,k S_{k+1} + P_u,k E_k,   lb_k = T_min - P_k - P_a,k s_k - P_b,k s_{k+1},
 * written into the rows r0 + k np .. of A (n_rows x NUS, column-major) and lb. */
static void ncgen_condense_taut(const casadi_real* P, const casadi_real* Pa, const casadi_real* Pb,
                                const casadi_real* Pu, casadi_real T_min, const casadi_real* S, const casadi_real* s,
                                int n_rows, int r0, casadi_real* A, casadi_real* lb) {
    const int nx = NCGEN_MPC_NX, nu = NCGEN_MPC_NU, np = NCGEN_MPC_PULLS;
    int i, j, k, c;
    for (k = 0; k < NCGEN_MPC_N; ++k)
        for (i = 0; i < np; ++i) {
            const casadi_real *a = Pa + k * nx * np + i, *b = Pb + k * nx * np + i;   /* row i, stride np */
            const int row = r0 + k * np + i;
            casadi_real r = T_min - P[k * np + i];
            for (j = 0; j < nx; ++j) r -= a[j * np] * s[k * nx + j] + b[j * np] * s[(k + 1) * nx + j];
            lb[row] = r;
            for (c = 0; c < NUS; ++c) {              /* S_k's nonzero columns: c < k nu; S_{k+1}'s: c < (k + 1) nu */
                const casadi_real *S_k = S + c * NXS + k * nx, *S_k1 = S_k + nx;
                casadi_real v = 0.0;
                if (c >= (k + 1) * nu) {
                    A[row + n_rows * c] = 0.0;
                    continue;
                }
                for (j = 0; j < nx; ++j) v += b[j * np] * S_k1[j];
                if (c < k * nu)
                    for (j = 0; j < nx; ++j) v += a[j * np] * S_k[j];
                else
                    v += Pu[c * np + i];
                A[row + n_rows * c] = v;
            }
        }
}
#endif
