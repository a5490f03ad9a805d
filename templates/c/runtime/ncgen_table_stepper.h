/* The compiled stepper of any model made of the element kinds ncgen ships, driven by tables:
 * the stepper's kernels (ncgen/assembly/stepper_equations.py documents them: step_newton,
 * step_velocity, step_check, step_solve, step_project, step_power, step_outputs) written once
 * as loops over a model's tables, and the model-independent RATTLE runtime (ncgen_rattle.h,
 * ncgen_fixed.h, ncgen_adaptive.h) included around them.  A model is data
 * (ncgen_stepper_tables, packed by ncgen/codegen/stepper_tables.py); the runtime's sizes
 * (NQ, NC, ...) read the tables of the run in progress, which the entry points set
 * (tab_cur, one per thread).
 *
 * Forces covered (F(t, q, v) without inputs or parameters):
 *   gravity         a constant generalised force f_gravity (nq); V = v_gravity − f_gravityᵀ q;
 *   springs         linear spring-dampers between two features a, b (points, f = G q + g):
 *                   the kernel TAB_SPRING (x = [r_a; r_b; ṙ_a; ṙ_b; k; l0; c]) gives the
 *                   force f on b (−f on a), its energy V and the power P = −c l̇² of its
 *                   damper, and J = ∂f/∂[r_a; r_b; ṙ_a; ṙ_b] (dim x 4 dim, column-major);
 *                   Q = G_bᵀ f − G_aᵀ f;
 *   inputs          forces linear in the inputs u with a constant map: Q = B_u u, B_u (nq x nu,
 *                   CSC bu_colind, bu_row, bu_val) summed over the model's input forces
 *                   (tab_input_forces; they do the power vᵀ B_u u);
 *   actuators       the efforts τ_j = act_tau_jᵀ u of actuated joints (Revolute, Prismatic) on
 *                   their coordinate θ_j(q): Q = Σ_j τ_j ∇θ_j.  θ_j is a quadratic form of the
 *                   k_j ≤ TAB_ACT_MAX_K coordinates act_col[act_ptr[j] ..] it touches (act_kind 0,
 *                   a slider's displacement) or atan2(y, x) of two such forms (act_kind 1, a
 *                   hinge's angle); act_form[act_form_ptr[j] ..] holds each form as
 *                   [c0; g (k); H (k x k, column-major)], value c0 + gᵀ q_j + ½ q_jᵀ H q_j.
 *   f_const         a constant generalised force (nq; constant PointForces, GeneralizedForces
 *                   of numbers), not part of V: its power vᵀ f_const counts in P;
 *   force elements over features (ff_*: cables, torsional spring-dampers): element e of kind
 *                   TAB_FEATURE_FORCES[ff_kind[e]] (kernel x = [f_1..f_n; ḟ_1..ḟ_n; numbers]
 *                   -> y = [g (n dim); V; P], J = ∂g/∂ḟ) acts on the features
 *                   ff_feat[ff_feat_ptr[e] ..] with the numbers ff_par[ff_par_ptr[e] ..]:
 *                   Q = Σ_X G_Xᵀ g_X, its damping's products ff_kpos, ff_kcoef, ff_kj (below);
 *   torques         a constant couple tq_val (3 per torque in 3D, 1 in 2D) on member
 *                   tq_member[e]: Q_I = W(q_I)ᵀ τ by the kernel TAB_TORQUES[mem_kind] (x =
 *                   [q_I; c_W; τ], c_W = tq_c[tq_c_ptr[e] ..]); its power v_Iᵀ Q_I counts in P.
 * The Newton matrix K = [[M − h/2 ∂F/∂w, A(q)ᵀ], [A(q + h w), 0]] (nq + nc square) is kept in
 * one CSC pattern: k_mpos, k_apos, k_atpos give the nonzero of K of each nonzero of M, of
 * A (lower block) and of Aᵀ (upper block); the dampers' products of each force are worked out
 * once per model (ncgen/codegen/stepper_tables.py: _velocity_entries), product k of spring s
 * (spr_kpos_ptr[s] <= k < spr_kpos_ptr[s + 1]) being K[spr_kpos[k]] += kscale spr_kcoef[k]
 * J[spr_kj[k]] with its kernel's J (ff_kpos, ff_kcoef, ff_kj the same for the force elements); it is solved by the sparse LU of ncgen_sparse_lu.h (the analysis
 * lu: each multiplier ordered after the coordinates its constraint touches; lu.n = 0: none),
 * or, where that LU finds an unsafe pivot (K singular or too ill-conditioned for its order),
 * by the sparse QR of ncgen_sparse_qr.h (stable in any order).
 *
 * Nonsmooth contacts (the contact library, built with NCGEN_CONTACTS defined): the contact
 * impulse j of ncgen_contact.h in step_newton (−j/2) and step_velocity (+j/2), the contact rows
 * from the run's contact tables S->ct (ncgen_table_contacts.h lists what it reads).
 *
 * What the including file defines first: casadi_real, casadi_int; TAB_KINDS (a const
 * ncgen_kinds *), TAB_SPRING_2D and TAB_SPRING_3D (kernels); TAB_FEATURE_FORCES (a const
 * ncgen_feature_force_kind *), TAB_TORQUES (a const ncgen_torque_kind * indexed by member kind),
 * TAB_FF_IN and TAB_FF_OUT (the largest input and outputs of those kernels); the status codes and
 * step_options of the stepper (as templates/c/stepper.c.j2 does); MAX_HALVINGS, NSTATS. */
#ifndef NCGEN_TABLE_STEPPER_H
#define NCGEN_TABLE_STEPPER_H

#include <math.h>
#include <stdlib.h>
#include <string.h>

#include "ncgen_element_tables.h"
#include "ncgen_sparse_lu.h"
#include "ncgen_sparse_qr.h"

/* Nonsmooth contacts (ncgen_table_contacts.h; packed by ncgen/codegen/contact_tables.py): nk
 * point contacts in ne elements (ns distinct member sides), the element table of
 * ncgen_contact_pairs.h (pair_*, its largest element max_q, max_g, max_w), W's pattern by rows
 * (wt_colind, wt_row: nnz_w), per point contact μ, e, its kind (pk_kind, an index of the
 * library's pair kinds), whether the kind's first side is the element's second (pk_swap) and
 * its numbers (pk_c from pk_c_ptr), per element side the map B of its local coordinates to its
 * kind's canonical ones (cm_n rows; its nonzeros cm_ptr[s] .. cm_ptr[s + 1] − 1 of side s = 2 e
 * + k, B[cm_row, cm_col] = cm); |g| (m/s²); schur 1 when the constant M is regular, then
 * minv = M⁻¹ (nq x nq, column-major) and its nonzeros by columns (minv_colind, minv_row), and
 * a_col, the column of each nonzero of A (the Delassus matrix by the Schur complement of
 * ncgen_contact.h; schur 0: by KKT solves). */
struct ncgen_contact_tables {
  int nk, ne, ns, max_q, max_g, max_w, nnz_w, schur;
  double gravity_norm;
  const int *wt_colind, *wt_row, *pair_int, *pair_qidx, *pair_wpos, *pair_side, *pair_sid, *pair_srep, *pk_kind,
      *pk_swap, *pk_c_ptr, *cm_ptr, *cm_n, *cm_row, *cm_col, *minv_colind, *minv_row, *a_col;
  const double *mu, *restitution, *pair_qconst, *pair_bdata, *pair_bound, *pk_c, *cm, *minv;
};

typedef struct {
  const ncgen_tables *T;            /* Φ, A and M: the element tables */
  int nu, np, n_markers, n_spring;
  double mass_scale;                /* max |M_ij| (kg) */
  int m_nnz;                        /* nonzero entries of M */
  const int *a_colind, *a_row;      /* the CSC pattern of A (nc x nq) of T */
  const int *m_colind, *m_row;      /* the CSC pattern of M's nonzero entries (nq x nq) */
  const double *m_val;              /* their values */
  const double *f_gravity;          /* nq */
  double v_gravity;                 /* J */
  const int *spr_feat;              /* 2 per spring: the features of its ends a, b */
  const double *spr_par;            /* 3 per spring: k (N/m), rest length (m), damping (N s/m) */
  const int *spr_kpos_ptr, *spr_kpos;  /* the dampers' products: spr_kpos_ptr[s] .. of spring s */
  const double *spr_kcoef;          /* K[spr_kpos[k]] += kscale spr_kcoef[k] J[spr_kj[k]] */
  const int *spr_kj;
  const int *marker_feat;           /* n_markers features */
  int nnz_k, nnz_v, nnz_r;
  const int *k_mpos, *k_apos, *k_atpos;
  const int *bu_colind, *bu_row;    /* the CSC pattern of B_u (nq x nu), the input forces' map */
  const double *bu_val;             /* its nonzeros */
  int n_act;                        /* actuated joints (above) */
  const int *act_kind, *act_ptr, *act_col, *act_form_ptr;
  const double *act_form, *act_tau; /* act_tau: nu per actuated joint */
  const double *f_const;            /* nq (NULL: none): constant generalised force, not in V */
  int n_ff;                         /* force elements over features */
  const int *ff_kind, *ff_feat_ptr, *ff_feat, *ff_par_ptr;
  const double *ff_par;
  const int *ff_kpos_ptr, *ff_kpos;  /* the dampers' products, as spr_kpos .. spr_kj */
  const double *ff_kcoef;
  const int *ff_kj;
  int n_torque;                     /* constant couples */
  const int *tq_member, *tq_c_ptr;
  const double *tq_c, *tq_val;
  ncgen_qr_pattern qr;              /* n = nq + nc, the pattern of K and its analysis */
  ncgen_lu_pattern lu;              /* n = nq + nc (or 0: QR only), the LU's analysis of that pattern */
  const struct ncgen_contact_tables *ct; /* nonsmooth contacts (NULL: none; the library built with
                                            NCGEN_CONTACTS needs them) */
} ncgen_stepper_tables;

#if defined(__STDC_VERSION__) && __STDC_VERSION__ >= 201112L
#define TAB_THREAD _Thread_local
#else
#define TAB_THREAD __thread
#endif
/* The tables of the run in progress in this thread. */
static TAB_THREAD const ncgen_stepper_tables *tab_cur;
/* The run's element work size and its cache of Φ and A at the last two q (a step evaluates
 * them at q, then at q + h w in each Newton iteration, and the step's end q⁺ is the last
 * of those): slot k holds q, Φ(q), A(q) at tab_cache[k] (nq + nc + a_nnz doubles). */
static TAB_THREAD long tab_ew_size;
static TAB_THREAD double *tab_cache[2];
static TAB_THREAD int tab_valid[2], tab_recent;
/* The forces' terms that depend on q alone, at the last q (a step's Newton iterations keep q,
 * and its velocity stage's q⁺ is the next step's q): q, the features at q (nf dim) and the
 * torques' generalised force (nq), at tab_qcache; tab_qvalid whether it holds them. */
static TAB_THREAD double *tab_qcache;
static TAB_THREAD int tab_qvalid;
/* The sparse LU of the last K that step_solve factored (tab_lu: K's nonzeros, then L, U and
 * the diagonal), reused while K is the same (the contact solve's one KKT solve per active row,
 * ncgen_contact.h: delassus_kkt); tab_lu_valid whether it holds one. */
static TAB_THREAD double *tab_lu;
static TAB_THREAD int tab_lu_valid;

/* Starts a run on the tables S in this thread: 0, or 1 when out of memory. */
static int tab_begin(const ncgen_stepper_tables *S) {
  size_t n = (size_t)S->T->nq + (size_t)S->T->nc + (size_t)S->T->a_nnz;
  size_t nqc = 2 * (size_t)S->T->nq + (size_t)S->T->nf * (size_t)S->T->dim;
  size_t nlu = S->lu.n ? (size_t)S->nnz_k + 2 * (size_t)S->lu.nnz_l + (size_t)S->lu.n : 0;
  tab_cur = S;
  tab_ew_size = ncgen_tables_work_size(TAB_KINDS, S->T);
  tab_cache[0] = malloc((2 * n + nqc + nlu) * sizeof(double) + 1);
  tab_cache[1] = tab_cache[0] ? tab_cache[0] + n : 0;
  tab_qcache = tab_cache[0] ? tab_cache[0] + 2 * n : 0;
  tab_lu = tab_cache[0] ? tab_qcache + nqc : 0;
  tab_valid[0] = tab_valid[1] = tab_qvalid = tab_lu_valid = 0;
  tab_recent = 0;
  return tab_cache[0] == 0;
}

/* Ends the run of tab_begin. */
static void tab_end(void) {
  free(tab_cache[0]);
  tab_cache[0] = tab_cache[1] = tab_qcache = tab_lu = 0;
  tab_valid[0] = tab_valid[1] = tab_qvalid = tab_lu_valid = 0;
}

/* The spring kernel's input and outputs at most (3D): x, then y = [f; V; P] and J. */
#define TAB_SPRING_IN (4 * 3 + 3)
#define TAB_SPRING_OUT (3 + 2 + 3 * 12)

#ifdef NCGEN_CONTACTS
/* The work of tab_pair_eval (ncgen_table_contacts.h, doubles): the kind's kernel work, the
 * canonical coordinates of both sides, a kind's input, its gap and its rows (dim x 2 TAB_PAIR_QC
 * at most). */
#define TAB_PAIR_WORK (TAB_PAIR_W + 4 * TAB_PAIR_QC + 1 + 6 * TAB_PAIR_QC)
#endif

/* The kernel work (doubles) of the tables S: element work, q + h w, F, the features
 * at q and their rates, the spring kernel's input and outputs, the QR factors and scratch
 * (the LU's factors are the run's, tab_lu). */
static long tab_work_size(const ncgen_stepper_tables *S) {
  const ncgen_tables *T = S->T;
  long n = T->nq + T->nc;
  return tab_ew_size + 2L * T->nq + 2L * T->nf * T->dim + TAB_SPRING_IN + TAB_SPRING_OUT + S->nnz_v + S->nnz_r +
         3 * n + TAB_FF_IN + TAB_FF_OUT
#ifdef NCGEN_CONTACTS
         + TAB_PAIR_WORK
#endif
      ;
}

typedef struct {
  double *ew, *qh, *F, *fq, *fv, *sx, *sy, *V, *R, *beta, *x, *y, *fx, *fy;
} tab_work;

static tab_work tab_layout(double *w) {
  const ncgen_stepper_tables *S = tab_cur;
  const ncgen_tables *T = S->T;
  tab_work b;
  b.ew = w;
  b.qh = b.ew + tab_ew_size;
  b.F = b.qh + T->nq;
  b.fq = b.F + T->nq;
  b.fv = b.fq + (size_t)T->nf * T->dim;
  b.sx = b.fv + (size_t)T->nf * T->dim;
  b.sy = b.sx + TAB_SPRING_IN;
  b.V = b.sy + TAB_SPRING_OUT;
  b.R = b.V + S->nnz_v;
  b.beta = b.R + S->nnz_r;
  b.x = b.beta + T->nq + T->nc;
  b.y = b.x + T->nq + T->nc;
  b.fx = b.y + T->nq + T->nc;
  b.fy = b.fx + TAB_FF_IN;
  return b;
}

/* Φ(q) and A(q): pointers into the cache (valid until the next call but one). */
static int tab_phi_jacobian(const double *q, const double **phi, const double **A, double *ew) {
  const ncgen_tables *T = tab_cur->T;
  size_t nq = (size_t)T->nq;
  int k;
  for (k = 0; k < 2; ++k)
    if (tab_valid[k] && !memcmp(q, tab_cache[k], nq * sizeof(double))) break;
  if (k == 2) {
    k = 1 - tab_recent;
    tab_valid[k] = 0;
    memcpy(tab_cache[k], q, nq * sizeof(double));
    if (ncgen_tables_phi_jacobian(TAB_KINDS, T, q, tab_cache[k] + nq, tab_cache[k] + nq + T->nc, ew)) return 1;
    tab_valid[k] = 1;
  }
  tab_recent = k;
  *phi = tab_cache[k] + nq;
  *A = tab_cache[k] + nq + T->nc;
  return 0;
}

/* The constant forces, the force elements over features and the torques (see the top of
 * this file), as tab_forces: added into F, kscale ∂F/∂v into K, energies into *V, powers into
 * *P (each if not NULL); the features at q and v already in b->fq, b->fv; v NULL: at rest;
 * q_cached: the torques' Q at this q already in tab_qcache (else computed into it). */
static int tab_feature_forces(const double *q, const double *v, double *F, double *K, double kscale, double *V,
                              double *P, int q_cached, tab_work *b) {
  const ncgen_stepper_tables *S = tab_cur;
  const ncgen_tables *T = S->T;
  int dim = T->dim, el, i, j, X, e;
  if (F && S->f_const)                   /* f_const NULL: no constant load */
    for (i = 0; i < T->nq; ++i) F[i] += S->f_const[i];
  if (P && v && S->f_const)
    for (i = 0; i < T->nq; ++i) *P += v[i] * S->f_const[i];
  for (el = 0; el < S->n_ff; ++el) {
    const ncgen_feature_force_kind *k = &TAB_FEATURE_FORCES[S->ff_kind[el]];
    const int *f = S->ff_feat + S->ff_feat_ptr[el];
    int nd = k->n_feat * dim;
    const double *arg[1];
    double *res[2], *J = b->fy + nd + 2;
    for (X = 0; X < k->n_feat; ++X) {
      memcpy(b->fx + X * dim, b->fq + f[X] * dim, sizeof(double) * (size_t)dim);
      memcpy(b->fx + nd + X * dim, b->fv + f[X] * dim, sizeof(double) * (size_t)dim);
    }
    memcpy(b->fx + 2 * nd, S->ff_par + S->ff_par_ptr[el], sizeof(double) * (size_t)k->n_par);
    arg[0] = b->fx;
    res[0] = b->fy;
    res[1] = J;
    if (k->eval(arg, res, 0, b->ew, 0)) return 1;
    if (V) *V += b->fy[nd];
    if (P) *P += b->fy[nd + 1];
    if (F)
      for (X = 0; X < k->n_feat; ++X)
        for (e = T->feat_ptr[f[X]]; e < T->feat_ptr[f[X] + 1]; ++e)
          F[T->feat_col[e]] += T->feat_coef[e] * b->fy[X * dim + T->feat_row[e]];
    if (K)                              /* ∂Q_col(e)/∂v_col(e2) = G_e (∂g_i/∂ḟ_Y,j) G_e2 */
      for (e = S->ff_kpos_ptr[el]; e < S->ff_kpos_ptr[el + 1]; ++e)
        K[S->ff_kpos[e]] += kscale * S->ff_kcoef[e] * J[S->ff_kj[e]];
  }
  if (!S->n_torque) return 0;
  if (!q_cached) {                       /* the torques' Q at q into the cache */
    double *Q = tab_qcache + T->nq + (size_t)T->nf * dim;
    memset(Q, 0, sizeof(double) * (size_t)T->nq);
    for (el = 0; el < S->n_torque; ++el) {
      int m = S->tq_member[el], base = T->mem_q_ptr[m];
      const ncgen_torque_kind *k = &TAB_TORQUES[T->mem_kind[m]];
      int nq_i = TAB_KINDS->member[T->mem_kind[m]].n_q, n_tau = dim == 3 ? 3 : 1;
      const double *arg[1];
      double *res[1];
      for (j = 0; j < nq_i; ++j)
        b->fx[j] = T->mem_q_col[base + j] >= 0 ? q[T->mem_q_col[base + j]] : T->mem_q_const[base + j];
      memcpy(b->fx + nq_i, S->tq_c + S->tq_c_ptr[el], sizeof(double) * (size_t)k->n_c);
      memcpy(b->fx + nq_i + k->n_c, S->tq_val + n_tau * el, sizeof(double) * (size_t)n_tau);
      arg[0] = b->fx;
      res[0] = b->fy;
      if (k->eval(arg, res, 0, b->ew, 0)) return 1;
      for (j = 0; j < nq_i; ++j)
        if (T->mem_q_col[base + j] >= 0) Q[T->mem_q_col[base + j]] += b->fy[j];
    }
  }
  for (i = 0; i < T->nq; ++i) {
    double Qi = tab_qcache[T->nq + (size_t)T->nf * dim + i];
    if (F) F[i] += Qi;
    if (P && v) *P += v[i] * Qi;
  }
  return 0;
}

/* F(q, v) into F (nq, if not NULL): gravity, tab_feature_forces and the springs; kscale ∂F/∂v
 * added into K (if not NULL) at ff_kpos and spr_kpos; the energies added to *V and the powers
 * to *P (if not NULL).
 * v NULL: at rest. */
static int tab_forces(const double *q, const double *v, double *F, double *K, double kscale, double *V, double *P,
                      tab_work *b) {
  const ncgen_stepper_tables *S = tab_cur;
  const ncgen_tables *T = S->T;
  int dim = T->dim, s, X, e;
  ncgen_kernel spring = dim == 3 ? TAB_SPRING_3D : TAB_SPRING_2D;
  size_t nfd = (size_t)T->nf * (size_t)dim;
  int q_cached = tab_qvalid && !memcmp(q, tab_qcache, sizeof(double) * (size_t)T->nq);
  if (F) memcpy(F, S->f_gravity, sizeof(double) * (size_t)T->nq);
  if (!q_cached) {
    tab_qvalid = 0;
    memcpy(tab_qcache, q, sizeof(double) * (size_t)T->nq);
    if (S->n_spring || S->n_ff) ncgen_tables_features(T, q, tab_qcache + T->nq, T->feat_const);
  }
  if (S->n_spring || S->n_ff) {
    memcpy(b->fq, tab_qcache + T->nq, sizeof(double) * nfd);
    if (v) ncgen_tables_features(T, v, b->fv, 0);
    else memset(b->fv, 0, sizeof(double) * nfd);
  }
  if (tab_feature_forces(q, v, F, K, kscale, V, P, q_cached, b)) return 1;
  tab_qvalid = 1;
  if (!S->n_spring) return 0;
  for (s = 0; s < S->n_spring; ++s) {
    const int *f = S->spr_feat + 2 * s;
    const double *arg[1];
    double *res[2], *J = b->sy + dim + 2;
    for (X = 0; X < 2; ++X) {
      memcpy(b->sx + X * dim, b->fq + f[X] * dim, sizeof(double) * (size_t)dim);
      memcpy(b->sx + (2 + X) * dim, b->fv + f[X] * dim, sizeof(double) * (size_t)dim);
    }
    memcpy(b->sx + 4 * dim, S->spr_par + 3 * s, 3 * sizeof(double));
    arg[0] = b->sx;
    res[0] = b->sy;
    res[1] = J;
    if (spring(arg, res, 0, b->ew, 0)) return 1;
    if (V) *V += b->sy[dim];
    if (P) *P += b->sy[dim + 1];
    if (F)
      for (X = 0; X < 2; ++X) {
        double sign = X ? 1.0 : -1.0;
        for (e = T->feat_ptr[f[X]]; e < T->feat_ptr[f[X] + 1]; ++e)
          F[T->feat_col[e]] += sign * T->feat_coef[e] * b->sy[T->feat_row[e]];
      }
    if (K)                           /* ∂Q_col(e)/∂v_col(e2) = sign G_e (∂f_i/∂ṙ_Y,j) G_e2 */
      for (e = S->spr_kpos_ptr[s]; e < S->spr_kpos_ptr[s + 1]; ++e)
        K[S->spr_kpos[e]] += kscale * S->spr_kcoef[e] * J[S->spr_kj[e]];
  }
  return 0;
}

#define TAB_ACT_MAX_K 32

/* The effort act_tau_jᵀ u of actuated joint j (u NULL: 0). */
static double tab_act_tau(int j, const double *u) {
  const ncgen_stepper_tables *S = tab_cur;
  double tau = 0;
  int i;
  if (!u) return 0;
  for (i = 0; i < S->nu; ++i) tau += S->act_tau[(size_t)j * S->nu + i] * u[i];
  return tau;
}

/* A quadratic form [c0; g; H] of k local coordinates ql: its value, its gradient into grad
 * and, if dl is not NULL, H dl into hd. */
static double tab_act_form(const double *form, int k, const double *ql, const double *dl, double *grad, double *hd) {
  const double *g = form + 1, *H = form + 1 + k;
  double val = form[0];
  int r, c;
  for (r = 0; r < k; ++r) {
    grad[r] = g[r];
    if (dl) hd[r] = 0;
  }
  for (c = 0; c < k; ++c)
    for (r = 0; r < k; ++r) {
      grad[r] += H[r + k * c] * ql[c];
      if (dl) hd[r] += H[r + k * c] * dl[c];
    }
  for (r = 0; r < k; ++r) val += (g[r] + grad[r]) / 2 * ql[r];
  return val;
}

/* The gradient ∇θ_j (k_j, local) of actuated joint j's coordinate at q and, if dq is not
 * NULL, (∇²θ_j) dq into hd; returns k_j. */
static int tab_act_gradient(int j, const double *q, const double *dq, double *grad, double *hd) {
  const ncgen_stepper_tables *S = tab_cur;
  const int lo = S->act_ptr[j], k = S->act_ptr[j + 1] - lo, *col = S->act_col + lo;
  const double *form = S->act_form + S->act_form_ptr[j];
  double ql[TAB_ACT_MAX_K], dl[TAB_ACT_MAX_K], gx[TAB_ACT_MAX_K], gy[TAB_ACT_MAX_K], hx[TAB_ACT_MAX_K],
      hy[TAB_ACT_MAX_K], x, y, r2, dx = 0, dy = 0;
  int i;
  for (i = 0; i < k; ++i) {
    ql[i] = q[col[i]];
    dl[i] = dq ? dq[col[i]] : 0;
  }
  if (S->act_kind[j] == 0) {
    tab_act_form(form, k, ql, dq ? dl : 0, grad, hd);
    return k;
  }
  x = tab_act_form(form, k, ql, dl, gx, hx);         /* θ = atan2(y, x) */
  y = tab_act_form(form + 1 + k + k * k, k, ql, dl, gy, hy);
  r2 = x * x + y * y;
  for (i = 0; i < k; ++i) {
    grad[i] = (x * gy[i] - y * gx[i]) / r2;
    dx += gx[i] * dl[i];
    dy += gy[i] * dl[i];
  }
  if (dq)
    for (i = 0; i < k; ++i)
      hd[i] = (dx * gy[i] + x * hy[i] - dy * gx[i] - y * hx[i]) / r2 - grad[i] * 2 * (x * dx + y * dy) / r2;
  return k;
}

/* The input forces at q added to F (nq): B_u u and the actuators' Σ τ_j ∇θ_j (nothing without
 * inputs). */
static void tab_input_forces(const double *q, const double *u, double *F) {
  const ncgen_stepper_tables *S = tab_cur;
  double grad[TAB_ACT_MAX_K];
  int j, k;
  if (!S->nu || !u) return;
  for (j = 0; j < S->nu; ++j)
    for (k = S->bu_colind[j]; k < S->bu_colind[j + 1]; ++k) F[S->bu_row[k]] += S->bu_val[k] * u[j];
  for (j = 0; j < S->n_act; ++j) {
    double tau = tab_act_tau(j, u);
    int n = tab_act_gradient(j, q, 0, grad, 0);
    for (k = 0; k < n; ++k) F[S->act_col[S->act_ptr[j] + k]] += tau * grad[k];
  }
}

/* vᵀ Q of the input forces at (q, v): their power (W). */
static double tab_input_power(const double *q, const double *v, const double *u) {
  const ncgen_stepper_tables *S = tab_cur;
  double P = 0, grad[TAB_ACT_MAX_K];
  int j, k;
  if (!S->nu || !u || !v) return 0;
  for (j = 0; j < S->nu; ++j)
    for (k = S->bu_colind[j]; k < S->bu_colind[j + 1]; ++k) P += v[S->bu_row[k]] * S->bu_val[k] * u[j];
  for (j = 0; j < S->n_act; ++j) {
    double tau = tab_act_tau(j, u);
    int n = tab_act_gradient(j, q, 0, grad, 0);
    for (k = 0; k < n; ++k) P += tau * grad[k] * v[S->act_col[S->act_ptr[j] + k]];
  }
  return P;
}

/* M x added to y (nq). */
static void tab_mass_times(const double *x, double *y) {
  const ncgen_tables *T = tab_cur->T;
  int j, k;
  for (j = 0; j < T->nq; ++j)
    for (k = tab_cur->m_colind[j]; k < tab_cur->m_colind[j + 1]; ++k) y[tab_cur->m_row[k]] += tab_cur->m_val[k] * x[j];
}

/* K = [[M, Aᵀ], [A, 0]]: the A of the lower block from lower, of the upper from upper. */
static void tab_kkt(double *K, const double *lower, const double *upper) {
  const ncgen_stepper_tables *S = tab_cur;
  int k;
  memset(K, 0, sizeof(double) * (size_t)S->nnz_k);
  for (k = 0; k < S->m_nnz; ++k) K[S->k_mpos[k]] = S->m_val[k];
  for (k = 0; k < S->T->a_nnz; ++k) {
    K[S->k_atpos[k]] = upper[k];
    K[S->k_apos[k]] = lower[k];
  }
}

/* y = A x (nc) or y += Aᵀ x (nq, transpose) for A's nonzeros a. */
static void tab_a_times(const double *a, const double *x, double *y, int transpose) {
  const ncgen_tables *T = tab_cur->T;
  int j, k;
  if (!transpose) memset(y, 0, sizeof(double) * (size_t)T->nc);
  if (!x) return;
  for (j = 0; j < T->nq; ++j)
    for (k = tab_cur->a_colind[j]; k < tab_cur->a_colind[j + 1]; ++k) {
      if (transpose) y[j] += a[k] * x[tab_cur->a_row[k]];
      else y[tab_cur->a_row[k]] += a[k] * x[j];
    }
}

static double tab_norm_inf(const double *x, int n) {
  double m = 0;
  int i;
  for (i = 0; i < n; ++i) m = isnan(m) || fabs(x[i]) <= m ? m : fabs(x[i]);
  return m;
}

/* step_newton: t, q, v, u, p, h, w, lam_h -> r, K. */
static int tab_newton(const casadi_real **arg, casadi_real **res, casadi_int *iw, casadi_real *w, int mem) {
  const ncgen_tables *T = tab_cur->T;
  const double *q = arg[1], *v = arg[2], *wm = arg[6], *nu = arg[7], h = *arg[5];
  double *r = res[0], *K = res[1];
  const double *phi, *Ah, *Aq, *phi_q;
  tab_work b = tab_layout(w);
  int i, nq = T->nq;
  (void)iw; (void)mem;
  for (i = 0; i < nq; ++i) {             /* NULL inputs are zeros (CasADi's convention) */
    b.qh[i] = q[i] + h * (wm ? wm[i] : 0);
    b.x[i] = (wm ? wm[i] : 0) - (v ? v[i] : 0);
  }
  if (tab_phi_jacobian(q, &phi_q, &Aq, b.ew) || tab_phi_jacobian(b.qh, &phi, &Ah, b.ew)) return 1;
  if (K) tab_kkt(K, Ah, Aq);
  if (tab_forces(q, wm, b.F, K, -h / 2, 0, 0, &b)) return 1;
  tab_input_forces(q, arg[3], b.F);
  if (r) {
    memset(r, 0, sizeof(double) * (size_t)nq);
    tab_mass_times(b.x, r);
    for (i = 0; i < nq; ++i) r[i] -= h / 2 * b.F[i];
    tab_a_times(Aq, nu, r, 1);
#ifdef NCGEN_CONTACTS
    if (arg[8])                          /* half the contact impulse j = Wᵀ P */
      for (i = 0; i < nq; ++i) r[i] -= arg[8][i] / 2;
#endif
    for (i = 0; i < T->nc; ++i) r[nq + i] = phi[i] / h;
  }
  return 0;
}

/* step_velocity: t, q, w, u, p, h -> b = [M w + h/2 F(q, w); −Φ_t = 0], K = [[M, Aᵀ], [A, 0]]. */
static int tab_velocity(const casadi_real **arg, casadi_real **res, casadi_int *iw, casadi_real *w, int mem) {
  const ncgen_tables *T = tab_cur->T;
  const double *q = arg[1], *wm = arg[2], h = *arg[5];
  const double *phi, *A;
  tab_work b = tab_layout(w);
  int i;
  (void)iw; (void)mem;
  if (tab_phi_jacobian(q, &phi, &A, b.ew)) return 1;
  if (res[1]) tab_kkt(res[1], A, A);
  if (tab_forces(q, wm, b.F, 0, 0, 0, 0, &b)) return 1;
  tab_input_forces(q, arg[3], b.F);
  if (res[0]) {
    memset(res[0], 0, sizeof(double) * (size_t)(T->nq + T->nc));
    if (wm) tab_mass_times(wm, res[0]);
    for (i = 0; i < T->nq; ++i) res[0][i] += h / 2 * b.F[i];
#ifdef NCGEN_CONTACTS
    if (arg[6])
      for (i = 0; i < T->nq; ++i) res[0][i] += arg[6][i] / 2;
#endif
  }
  return 0;
}

/* Φ(q) and A(q) (cached, tab_phi_jacobian), A v (Φ_t = 0) into phidot (if not NULL). */
static int tab_constraints(const double *q, const double *v, double *phidot, const double **phi,
                           const double **A, tab_work *b) {
  if (tab_phi_jacobian(q, phi, A, b->ew)) return 1;
  if (phidot) tab_a_times(*A, v, phidot, 0);
  return 0;
}

/* step_check: t, q, v, p -> max |Φ|, max |A v + Φ_t|. */
static int tab_check(const casadi_real **arg, casadi_real **res, casadi_int *iw, casadi_real *w, int mem) {
  const double *phi, *A;
  tab_work b = tab_layout(w);
  (void)iw; (void)mem;
  if (tab_constraints(arg[1], arg[2], b.x, &phi, &A, &b)) return 1;
  if (res[0]) *res[0] = tab_norm_inf(phi, tab_cur->T->nc);
  if (res[1]) *res[1] = tab_norm_inf(b.x, tab_cur->T->nc);
  return 0;
}

/* step_project: t, q, v, p -> K = [[M, Aᵀ], [A, 0]], Φ, A v + Φ_t. */
static int tab_project(const casadi_real **arg, casadi_real **res, casadi_int *iw, casadi_real *w, int mem) {
  const double *phi, *A;
  tab_work b = tab_layout(w);
  (void)iw; (void)mem;
  if (tab_constraints(arg[1], arg[2], res[2], &phi, &A, &b)) return 1;
  if (res[0]) tab_kkt(res[0], A, A);
  if (res[1]) memcpy(res[1], phi, sizeof(double) * (size_t)tab_cur->T->nc);
  return 0;
}

/* step_solve: K, r -> K⁻¹ r: by the LU (kept for the next solve with the same K), or by the QR
 * where the LU's pivots are unsafe. */
static int tab_solve(const casadi_real **arg, casadi_real **res, casadi_int *iw, casadi_real *w, int mem) {
  const ncgen_stepper_tables *S = tab_cur;
  tab_work b = tab_layout(w);
  (void)iw; (void)mem;
  if (S->lu.n) {
    size_t nk = (size_t)S->nnz_k;
    double *l = tab_lu + nk, *u = l + S->lu.nnz_l, *d = u + S->lu.nnz_l;
    if (!tab_lu_valid || memcmp(tab_lu, arg[0], nk * sizeof(double))) {
      tab_lu_valid = 0;
      if (!ncgen_lu_factor(&S->lu, arg[0], l, u, d, b.x)) {
        memcpy(tab_lu, arg[0], nk * sizeof(double));
        tab_lu_valid = 1;
      }
    }
    if (tab_lu_valid) {
      ncgen_lu_solve(&S->lu, l, u, d, arg[1], res[0], b.y);
      return 0;
    }
  }
  if (ncgen_qr_factor(&tab_cur->qr, arg[0], b.V, b.R, b.beta, b.x)) {
    int i;                           /* singular: NaN, which the stepper reports as not finite */
    for (i = 0; i < tab_cur->qr.n; ++i) res[0][i] = NAN;
    return 0;
  }
  ncgen_qr_solve(&tab_cur->qr, b.V, b.R, b.beta, arg[1], res[0], b.y);
  return 0;
}

/* step_power: t, q, v, lam, u, p -> [P, P_contacts, P_friction, P_inputs, P_drives] with
 * P = vᵀ(F + ∇V) + ∂V/∂t + λᵀΦ_t (ncgen_rattle.h: NPOWER): the dampers' and constant loads'
 * power and the inputs' (no contacts, no drives on the tables). */
static int tab_power(const casadi_real **arg, casadi_real **res, casadi_int *iw, casadi_real *w, int mem) {
  tab_work b = tab_layout(w);
  double P = 0, Pu;
  (void)iw; (void)mem;
  if (tab_forces(arg[1], arg[2], 0, 0, 0, 0, &P, &b)) return 1;
  Pu = tab_input_power(arg[1], arg[2], arg[4]);
  if (res[0]) {
    res[0][0] = P + Pu;
    res[0][1] = res[0][2] = res[0][4] = 0;
    res[0][3] = Pu;
  }
  return 0;
}

/* step_outputs: t, q, v, lam, u, p -> [T; V; max |Φ|; max |A v + Φ_t|; P; markers]. */
static int tab_outputs(const casadi_real **arg, casadi_real **res, casadi_int *iw, casadi_real *w, int mem) {
  const ncgen_stepper_tables *S = tab_cur;
  const ncgen_tables *T = S->T;
  const double *q = arg[1], *v = arg[2];
  double *y = res[0], Tk = 0, V = S->v_gravity, P = 0;
  const double *phi, *A;
  tab_work b = tab_layout(w);
  int i, k;
  (void)iw; (void)mem;
  if (!y) return 0;
  memset(b.x, 0, sizeof(double) * (size_t)T->nq);
  if (v) tab_mass_times(v, b.x);
  for (i = 0; i < T->nq; ++i) {
    Tk += (v ? v[i] : 0) * b.x[i];
    V -= S->f_gravity[i] * q[i];
  }
  if (tab_forces(q, v, 0, 0, 0, &V, &P, &b)) return 1;
  P += tab_input_power(q, v, arg[4]);
  if (tab_constraints(q, v, b.x, &phi, &A, &b)) return 1;
  y[0] = Tk / 2;
  y[1] = V;
  y[2] = tab_norm_inf(phi, T->nc);
  y[3] = tab_norm_inf(b.x, T->nc);
  y[4] = P;
  if (S->n_markers) {
    ncgen_tables_features(T, q, b.fq, T->feat_const);
    for (k = 0; k < S->n_markers; ++k)
      memcpy(y + 5 + k * T->dim, b.fq + S->marker_feat[k] * T->dim, sizeof(double) * (size_t)T->dim);
  }
  return 0;
}

/* The kernels' sizes, as CasADi's <f>_work gives them. */
static int tab_work_sizes(casadi_int *sz_arg, casadi_int *sz_res, casadi_int *sz_iw, casadi_int *sz_w) {
#ifdef NCGEN_CONTACTS
  *sz_arg = 9;                       /* step_newton's contact impulse */
#else
  *sz_arg = 8;
#endif
  *sz_res = 3;
  *sz_iw = 0;
  *sz_w = tab_work_size(tab_cur);
  return 0;
}

#define NQ (tab_cur->T->nq)
#define NC (tab_cur->T->nc)
#define NU (tab_cur->nu)
#define NNZ_K (tab_cur->nnz_k)
#define MASS_SCALE (tab_cur->mass_scale)
#define NOUT (5 + tab_cur->T->dim * tab_cur->n_markers)
#define KERNEL_NEWTON tab_newton
#define KERNEL_VELOCITY tab_velocity
#define KERNEL_CHECK tab_check
#define KERNEL_SOLVE tab_solve
#define KERNEL_PROJECT tab_project
#define KERNEL_POWER tab_power
#define KERNEL_OUTPUTS tab_outputs
#define KERNEL_WORKS tab_work_sizes

#ifdef NCGEN_CONTACTS
#include "ncgen_table_contacts.h"
#endif
#include "ncgen_rattle.h"
#ifdef NCGEN_CONTACTS
#include "ncgen_cone_newton.h"
#include "ncgen_contact_pairs.h"
#include "ncgen_contact.h"
#endif
#include "ncgen_fixed.h"
#include "ncgen_adaptive.h"
#ifdef NCGEN_CONTACTS
/* the Schur complement's names of ncgen_table_contacts.h: fields of the stepper tables again */
#undef a_nz
#undef a_row
#undef a_col
#endif

#endif
