/* RATTLE for constant mass matrices: one step by Newton's method, its checks, the
 * projection onto the constraint manifold and the power of the forces, around the generated
 * kernels of one model.  Plain C99, model-independent: the model's stepper glue
 * (<model>_stepper.c, from templates/c/stepper.c.j2) defines the data below, then includes
 * ncgen_rattle.h, ncgen_contact.h (models with nonsmooth contacts), ncgen_fixed.h and
 * ncgen_adaptive.h, in this order, into one translation unit; every function here is static.
 * See <model>_stepper.h for the scheme, the convergence tests and the status codes.
 *
 * What the including file defines first:
 *   casadi_real, casadi_int    the kernels' types (the model's header)
 *   NQ, NC, NU                 coordinates, constraints, inputs
 *   NNZ_K                      nonzeros of the KKT matrix (output K of KERNEL_NEWTON)
 *   MASS_SCALE                 max |M_ij| (kg), the scale of the momentum residual
 *   MAX_HALVINGS               deepest step splitting the workspace allows
 *   NSTATS                     columns of a row of statistics (ncgen_fixed.h)
 *   STEP_OK .. STEP_INTERRUPTED  the status codes 0 .. 8 of <model>_stepper.h
 *   step_options               a struct with casadi_real tol, int max_iter, int max_halvings,
 *                              int scheme, volatile int *stop
 *   SCHEME_RATTLE4             the value of scheme that selects the fourth-order
 *                              composition (ncgen_fixed.h; 0: RATTLE)
 *   DEFAULT_OPTIONS()          an expression giving the default step_options
 *   KERNEL_NEWTON, KERNEL_VELOCITY, KERNEL_CHECK, KERNEL_SOLVE, KERNEL_PROJECT, KERNEL_POWER,
 *   KERNEL_OUTPUTS             the generated kernels (CasADi's calling convention
 *                              f(arg, res, iw, w, mem)); ncgen.assembly.stepper_equations
 *                              documents their inputs and outputs
 *   KERNEL_WORKS               the list of every kernel's _work function, comma-separated
 *   NCGEN_CONTACTS             defined for nonsmooth contacts, then also NOUT (values of
 *                              KERNEL_OUTPUTS) and what ncgen_contact.h lists
 */
#include <math.h>
#include <stdlib.h>
#include <string.h>

#define NX (NQ + NC)
/* The work of a step by class (ws->step_work, the statistics' columns 5 .. 5 + NWORK - 1):
 * all of it, then the smooth contacts' normal forces and nonsmooth normal impulses, the
 * friction forces and impulses, the inputs, the drives (rheonomic constraints and
 * time-dependent potentials), the dampers and every other force doing work outside V, and
 * the energy the push-out of penetrating contacts changed (ncgen_contact.h).  KERNEL_POWER
 * gives the powers of the first NPOWER classes (the dampers' is the total less the others). */
#define NPOWER 5
#define WORK_TOTAL 0
#define WORK_CONTACTS 1
#define WORK_FRICTION 2
#define WORK_INPUTS 3
#define WORK_DRIVES 4
#define WORK_DAMPERS 5
#define WORK_PUSH_OUT 6
#define NWORK 7
#ifdef NCGEN_CONTACTS
#define ND (NK * DC)
#endif
#define ALIGN 16

typedef int (*kernel_work)(casadi_int *sz_arg, casadi_int *sz_res, casadi_int *sz_iw, casadi_int *sz_w);

static const kernel_work kernel_works[] = {KERNEL_WORKS};
#define N_KERNELS (sizeof kernel_works / sizeof kernel_works[0])

/* Pointers into one workspace block. */
typedef struct {
  const casadi_real **arg;
  casadi_real **res;
  casadi_real *x;   /* Newton unknowns [w; h/2 lambda], then [v+; h/2 mu] */
  casadi_real *r;   /* residual, then right-hand side */
  casadi_real *dx;  /* Newton update */
  casadi_real *K;   /* KKT matrix nonzeros */
  casadi_real *chk; /* max |Phi|, max |A v + Phi_t|, power P */
  casadi_real *lam2; /* the last step's multipliers lambda (start) and mu (end), NC each */
  casadi_real *mid; /* states at the middle of split steps: [q; v] per splitting depth */
  casadi_real *sub; /* the two intermediate states [q; v] of a composed step */
#ifdef NCGEN_CONTACTS
  casadi_real *y;   /* KERNEL_OUTPUTS of one state (NOUT): the energy around a push-out */
#endif
  casadi_real *w;   /* kernel work */
  casadi_int *iw;
  int track_work;    /* whether step() sets step_work */
  casadi_real step_work[NWORK]; /* work of each class (WORK_*) over the last step (the forces':
                            h/2 (P(t, q, v, lambda) + P(t + h, q+, v+, mu)), each end with the
                            multiplier that acts there, second order; the impulses': exact,
                            ncgen_contact.h), or over the last composed or split step */
#ifdef NCGEN_CONTACTS
  casadi_real *j;    /* generalised contact impulse of the step's second half, W(q_free)^T P */
  casadi_real *j0;   /* ... and of its first half, W(q)^T P (the rows at the start of the step) */
  casadi_real *g;    /* gaps at the end of the free step */
  casadi_real *W;    /* contact Jacobian there: its NNZ_W nonzeros, by rows (wt_colind, wt_row) */
  casadi_real *W0;   /* the same at the start of the step */
  casadi_real *U;    /* contact velocities: at the end of the free step, then with the impulses */
  casadi_real *Um;   /* contact velocities at the start of the step (then ND more, scratch) */
  casadi_real *Pold; /* impulses of the previous refinement */
  casadi_real *Wr;   /* repeat_step()'s contact Jacobian at the start of the step (NNZ_W) */
  /* The contact solves' blocks, sized by the active rows: in ws->dyn, room for ws->ncap rows
   * (contact_reserve(); freed by workspace_free()) */
  char *dyn;
  int ncap;
  casadi_real *Xc;   /* [M A^T; A 0]^-1 [W_r^T; 0], first NQ rows, per active row r */
  casadi_real *G;    /* Delassus matrix of the active rows */
  casadi_real *S;    /* Cholesky factor of lcp_newton()'s submatrix of G (rows of n), or cone_newton()'s
                        Jacobian; S2 its Levenberg-Marquardt matrix (ncap^2 each) */
  casadi_real *S2;
  casadi_real *P;    /* impulses of the active rows */
  casadi_real *rhs;  /* right-hand side and solution of one solve, then a saved Newton start */
  casadi_real *Pacc; /* impulses per contact summed over the steps since last cleared */
  casadi_real *F;    /* mean contact forces P / h of the last step (warm start of the next) */
  casadi_real *fac;  /* QR factors V, R, beta of the KKT matrix */
  casadi_int *act;   /* active contacts */
  casadi_int *fset;  /* the rows of G whose Cholesky factor ws->S holds (fm of them), in its
                        order; at fset + NK the first nonzero column of each of its rows */
  int fm;            /* their number; -1 after delassus() changed G or cone_newton() used S */
  casadi_real *cn;   /* cone_newton(): rho, phi, dP, G dP, trial P and U, P and U it started from (ND each) */
  casadi_int *cni;   /* cone_newton(): the elimination's column list and dropped columns (ND
                        each); then delassus()'s scratch (Schur complement form) */
  casadi_int *gp, *gi; /* the nonzeros of G by columns: column r has rows gi[gp[r] .. gp[r + 1] - 1] (gi in ws->dyn) */
  casadi_int *zr;    /* delassus()'s Z by rows of L: the active rows (NC ncap, in ws->dyn) */
  int *kon;          /* the contacts evaluated (ascending; nkon of them): all, or with CONTACT_PAIRS those of
                        the elements on (ncgen_contact_pairs.h); the loops over contacts and rows walk them */
  int nkon;
  int *rowbuf;       /* contact_step()'s active rows (ND) */
  int *ksum;         /* the contacts whose impulse sums ws->Pacc are not zero (nsum of them; ncgen_contact.h) */
  int *psum;         /* ... per contact 1 if among them, else 0 */
  int nsum;
#ifdef CONTACT_SCHUR
  casadi_real *T;    /* A M^-1, NC x NQ, row-major */
  casadi_real *L;    /* Cholesky factor of A M^-1 A^T, NC x NC, column-major */
  casadi_real *Z;    /* L^-1 A M^-1 W_r^T, NC per active row r (in ws->dyn) */
  casadi_real *Y;    /* L^-T Z, NC per active row r (in ws->dyn) */
  int schur;         /* whether the last delassus() took the Schur complement (Xc holds M^-1 W_r^T) */
  int tl_zero;       /* whether T and L are zero but in the ranges the last delassus() recorded */
#endif
  long pgs_unconverged; /* contact solves that used impulses from pgs() at PGS_MAX_ITER, since cleared */
  casadi_real pgs_last; /* relative change of the last sweep of the last pgs() */
  casadi_real pgs_residual; /* the largest pgs_last of those solves */
  casadi_real cone_residual; /* the largest contact-law residual of a step's impulses, since cleared */
  casadi_real cone_last; /* cone_newton()'s last residual */
  casadi_real penetration; /* the deepest gap below 0 at the end of a step, since cleared (m) */
  int pgs_sweeps;       /* sweeps of the last pgs() before it converged */
  int repeat;           /* whether repeat_step() is worth trying: the last step's impulses were
                           its own warm start's, or repeated */
  int newton_once;      /* whether step() takes one Newton iteration even from a warm start
                           that passes its test (contact_step()'s steps with impulses) */
#ifdef CONTACT_PAIRS
  casadi_real *pq;   /* an element's local coordinates and rates (PAIR_MAX_Q each) */
  casadi_real *pg;   /* an element kernel's gaps (PAIR_MAX_G) */
  casadi_real *pw;   /* ... and its dense W (PAIR_MAX_W) */
  casadi_real *plb;  /* per element: the lower bound of its gaps at the last pairs_bounds() */
  casadi_real *pspd; /* ... and the bound of its rows' velocities */
  casadi_real *psb;  /* per distinct member side (PAIR_NS): x0 (DC), R, lin, rot at the last pairs_bounds() */
  casadi_real *pbq;  /* the q (NQ) of the last pairs_bounds() */
  int pb_rates;      /* whether it was given rates (1) or not (0); -1: none since layout() */
  int *pon;          /* per element: 0 skipped, 1 evaluated, 2 to be evaluated (ncgen_contact_pairs.h) */
  casadi_real *pint; /* the sweep (ncgen_contact_pairs.h): per distinct member side its box (lo, hi per axis: 2 DC) */
  int *pord;         /* ... the sides by lo on the sweep's axis, kept from the last sweep (PAIR_NS) */
  int *pover;        /* ... pairs_init()'s scratch (PAIR_NS) */
  int *padj;         /* ... per side the elements it is the first side of: CSR pointers (PAIR_NS + 1), then
                        (other side, element) by other side (2 NE) */
  int *palw;         /* ... the elements always bounded one by one (NE), their number in nalw */
  int nalw;          /* ... (-1: the tables not made since layout()) */
  int *pcand;        /* the candidates: the elements whose bound ws->plb was taken at the last sweep or that
                        are on, in the sweep's order (ncand); every other element is off with bound ws->plim */
  int ncand;
  int *pcm;          /* ... per element 1 if a candidate, else 0 */
  int *pld;          /* the elements that may carry a force (a superset: npld), known if pld_ok */
  int npld, pld_ok;
  casadi_real pkmin, pdmax; /* ... the least kappa and the largest d_min of the elements swept */
  casadi_real plim;  /* the level below which ws->plb is every element's lower bound (pairs_select()) */
  casadi_real *pcache; /* per element: its last kernel results (PAIR_SLOT, ncgen_contact_pairs.h) */
#endif
#endif
} workspace;

/* Blocks of the workspace (layout()). */
#ifdef CONTACT_PAIRS
#define N_BLOCKS 27
#elif defined(NCGEN_CONTACTS)
#define N_BLOCKS 26
#else
#define N_BLOCKS 10
#endif

static size_t align_up(size_t n) {
  return (n + ALIGN - 1) / ALIGN * ALIGN;
}

/* Kernel work sizes: the maximum over all kernels. */
static void kernel_sizes(casadi_int *sz_arg, casadi_int *sz_res, casadi_int *sz_iw, casadi_int *sz_w) {
  size_t k;
  *sz_arg = *sz_res = *sz_iw = *sz_w = 0;
  for (k = 0; k < N_KERNELS; ++k) {
    casadi_int a, r, i, w;
    kernel_works[k](&a, &r, &i, &w);
    if (a > *sz_arg) *sz_arg = a;
    if (r > *sz_res) *sz_res = r;
    if (i > *sz_iw) *sz_iw = i;
    if (w > *sz_w) *sz_w = w;
  }
}

/* Lays out the workspace in `block` (if not NULL) and returns its size in bytes. */
#ifdef CONTACT_PAIRS
/* Doubles per contact element of ws->pcache (ncgen_contact_pairs.h: pair_eval()): which of its
 * two entries goes next, then the two. */
#define PAIR_SLOT (3 + 2 * ((size_t) PAIR_MAX_Q + (size_t) PAIR_MAX_G + (size_t) PAIR_MAX_W))
#endif

static size_t layout(workspace *ws, char *block) {
  casadi_int sz_arg, sz_res, sz_iw, sz_w;
  size_t off[N_BLOCKS + 1], sizes[N_BLOCKS], k;
  kernel_sizes(&sz_arg, &sz_res, &sz_iw, &sz_w);
  sizes[0] = (size_t) sz_arg * sizeof(const casadi_real *);
  sizes[1] = (size_t) sz_res * sizeof(casadi_real *);
  sizes[2] = sizes[3] = sizes[4] = NX * sizeof(casadi_real);
  sizes[5] = NNZ_K * sizeof(casadi_real);
  sizes[6] = (3 + 2 * NC) * sizeof(casadi_real);
  sizes[7] = (size_t) sz_w * sizeof(casadi_real);
  sizes[8] = (size_t) sz_iw * sizeof(casadi_int);
  sizes[9] = (2 * NQ * MAX_HALVINGS + 4 * NQ) * sizeof(casadi_real);
#ifdef NCGEN_CONTACTS
  sizes[9] += NOUT * sizeof(casadi_real);
#endif
#ifdef NCGEN_CONTACTS
  sizes[10] = 2 * NQ * sizeof(casadi_real);
  sizes[11] = NK * sizeof(casadi_real);
  sizes[12] = 2 * NNZ_W * sizeof(casadi_real);
  sizes[15] = NNZ_W * sizeof(casadi_real);
  sizes[13] = sizes[17] = sizes[19] = ND * sizeof(casadi_real);
  sizes[14] = 4 * ND * sizeof(casadi_real); /* Um, the end-of-step velocities, Pold, its change */
  sizes[16] = 0; /* G, S, X, Z, Y: ws->dyn, by the active rows (contact_reserve()) */
  sizes[18] = 3 * NX * sizeof(casadi_real); /* rhs, solution, saved Newton start */
  sizes[20] = (NK + ND + NK + ND + 1) * sizeof(casadi_int) + /* act, fset (and the factor's row starts), gp */
              (NK + ND + 2 * NK) * sizeof(int); /* kon, rowbuf, ksum, psum */
  sizes[21] = ND * sizeof(casadi_real);
#ifdef CONTACT_FACTORED
  sizes[22] = (NNZ_V + NNZ_R + N_BETA) * sizeof(casadi_real);
#else
  sizes[22] = 0;
#endif
#ifdef CONTACT_SCHUR
  sizes[23] = (NC * NQ + NC * NC) * sizeof(casadi_real);
#else
  sizes[23] = 0;
#endif
  sizes[24] = 8 * ND * sizeof(casadi_real);
#ifdef CONTACT_SCHUR
  sizes[25] = (2 * ND + NC + 2 * ND + NQ + 1 + 2 * NNZ_W + 2 * NC + NQ + 1 + NNZ_A + 2 * ND + NC + NC + 1) *
              sizeof(casadi_int);
#else
  sizes[25] = 2 * ND * sizeof(casadi_int);
#endif
#ifdef CONTACT_PAIRS
  sizes[26] = (2 * PAIR_MAX_Q + PAIR_MAX_G + PAIR_MAX_W + 2 * NE + PAIR_NS * (3 * DC + 3) + NQ +
               (size_t) NE * PAIR_SLOT) * sizeof(casadi_real) + (7 * NE + 3 * PAIR_NS + 1) * sizeof(int);
#endif
#endif
  off[0] = 0;
  for (k = 0; k < N_BLOCKS; ++k) off[k + 1] = off[k] + align_up(sizes[k]);
  if (ws) {
    ws->arg = (const casadi_real **) (void *) (block + off[0]);
    ws->res = (casadi_real **) (void *) (block + off[1]);
    ws->x = (casadi_real *) (void *) (block + off[2]);
    ws->r = (casadi_real *) (void *) (block + off[3]);
    ws->dx = (casadi_real *) (void *) (block + off[4]);
    ws->K = (casadi_real *) (void *) (block + off[5]);
    ws->chk = (casadi_real *) (void *) (block + off[6]);
    ws->lam2 = ws->chk + 3;
    ws->track_work = 0;
    memset(ws->step_work, 0, sizeof ws->step_work);
    ws->w = (casadi_real *) (void *) (block + off[7]);
    ws->iw = (casadi_int *) (void *) (block + off[8]);
    ws->mid = (casadi_real *) (void *) (block + off[9]);
    ws->sub = ws->mid + 2 * NQ * MAX_HALVINGS;
#ifdef NCGEN_CONTACTS
    ws->y = ws->sub + 4 * NQ;
#endif
#ifdef NCGEN_CONTACTS
    ws->j = (casadi_real *) (void *) (block + off[10]);
    ws->j0 = ws->j + NQ;
    ws->g = (casadi_real *) (void *) (block + off[11]);
    ws->W = (casadi_real *) (void *) (block + off[12]);
    ws->W0 = ws->W + NNZ_W;
    ws->U = (casadi_real *) (void *) (block + off[13]);
    ws->Um = (casadi_real *) (void *) (block + off[14]);
    ws->Pold = ws->Um + 2 * ND;
    ws->Wr = (casadi_real *) (void *) (block + off[15]);
    ws->dyn = 0;
    ws->ncap = 0;
    ws->Xc = ws->G = ws->S = ws->S2 = 0; /* contact_reserve() */
    ws->gi = ws->zr = 0;
    ws->P = (casadi_real *) (void *) (block + off[17]);
    ws->rhs = (casadi_real *) (void *) (block + off[18]);
    ws->Pacc = (casadi_real *) (void *) (block + off[19]);
    ws->act = (casadi_int *) (void *) (block + off[20]);
    ws->fset = ws->act + NK;
    ws->gp = ws->fset + ND + NK;
    ws->kon = (int *) (void *) (ws->gp + ND + 1);
    ws->rowbuf = ws->kon + NK;
    ws->ksum = ws->rowbuf + ND;
    ws->psum = ws->ksum + NK;
    ws->nsum = 0;
    ws->nkon = 0;
    ws->fm = -1;
    ws->newton_once = 0;
    ws->F = (casadi_real *) (void *) (block + off[21]);
    ws->fac = (casadi_real *) (void *) (block + off[22]);
    ws->cn = (casadi_real *) (void *) (block + off[24]);
    ws->cni = (casadi_int *) (void *) (block + off[25]);
#ifdef CONTACT_PAIRS
    ws->pq = (casadi_real *) (void *) (block + off[26]);
    ws->pg = ws->pq + 2 * PAIR_MAX_Q;
    ws->pw = ws->pg + PAIR_MAX_G;
    ws->plb = ws->pw + PAIR_MAX_W;
    ws->pspd = ws->plb + NE;
    ws->psb = ws->pspd + NE;
    ws->pbq = ws->psb + PAIR_NS * (DC + 3);
    ws->pb_rates = -1;
    ws->pint = ws->pbq + NQ;
    ws->pcache = ws->pint + 2 * DC * PAIR_NS;
    for (k = 0; k < (size_t) NE; ++k) /* every entry empty */
      ws->pcache[k * PAIR_SLOT] = ws->pcache[k * PAIR_SLOT + 1] =
          ws->pcache[k * PAIR_SLOT + 2 + PAIR_MAX_Q + PAIR_MAX_G + PAIR_MAX_W] = 0;
    ws->pon = (int *) (void *) (ws->pcache + (size_t) NE * PAIR_SLOT);
    ws->pord = ws->pon + NE;
    ws->pover = ws->pord + PAIR_NS;
    ws->padj = ws->pover + PAIR_NS;
    ws->palw = ws->padj + PAIR_NS + 1 + 2 * NE;
    ws->nalw = -1;
    ws->pcand = ws->palw + NE;
    ws->pcm = ws->pcand + NE;
    ws->pld = ws->pcm + NE;
    ws->ncand = ws->npld = ws->pld_ok = 0;
    memset(ws->pon, 0, NE * sizeof(int));
    memset(ws->pcm, 0, NE * sizeof(int));
    ws->plim = -INFINITY;
#endif
#ifdef CONTACT_SCHUR
    ws->T = (casadi_real *) (void *) (block + off[23]);
    ws->L = ws->T + NC * NQ;
    ws->Z = ws->Y = 0; /* contact_reserve() */
    ws->tl_zero = 0;
#endif
#endif
  }
  return off[N_BLOCKS];
}

/* Bytes of workspace one step needs (with contacts, the blocks of the contact solves are
 * allocated as the active rows need them: contact_reserve()). */
static size_t step_work_bytes(void) {
  return layout(0, 0);
}

#ifdef NCGEN_CONTACTS
/* Room in ws->dyn for the contact solves of n active rows (n <= ND): G (n x n), S and S2 (n x n
 * each), X (NQ per row), the pattern of G (n x n), with the Schur complement Z and Y (NC per
 * row) and Z's rows (NC per row).  Grown to twice its rows (at most ND) when short; its content
 * is not kept (each solve writes it after this).  Returns 0, or 1 if it cannot be allocated. */
static int contact_reserve(workspace *ws, int n) {
  size_t c, bytes;
  char *b;
  if (n <= ws->ncap) return 0;
  c = (size_t) (2 * ws->ncap < ND ? 2 * ws->ncap : ND);
  if (c < (size_t) n) c = (size_t) n;
  bytes = align_up(3 * c * c * sizeof(casadi_real)) + align_up(c * NQ * sizeof(casadi_real)) +
          align_up(c * c * sizeof(casadi_int));
#ifdef CONTACT_SCHUR
  bytes += align_up(2 * NC * c * sizeof(casadi_real)) + align_up(NC * c * sizeof(casadi_int));
#endif
  free(ws->dyn);
  ws->ncap = 0;
  if (!(ws->dyn = b = malloc(bytes))) return 1;
  ws->ncap = (int) c;
  ws->G = (casadi_real *) (void *) b;
  ws->S = ws->G + c * c;
  ws->S2 = ws->S + c * c;
  b += align_up(3 * c * c * sizeof(casadi_real));
  ws->Xc = (casadi_real *) (void *) b;
  b += align_up(c * NQ * sizeof(casadi_real));
  ws->gi = (casadi_int *) (void *) b;
#ifdef CONTACT_SCHUR
  b += align_up(c * c * sizeof(casadi_int));
  ws->Z = (casadi_real *) (void *) b;
  ws->Y = ws->Z + NC * c;
  b += align_up(2 * NC * c * sizeof(casadi_real));
  ws->zr = (casadi_int *) (void *) b;
#endif
  return 0;
}
#endif

/* Frees what the steps allocated beyond the workspace block (the contact solves' blocks). */
static void workspace_free(workspace *ws) {
#ifdef NCGEN_CONTACTS
  free(ws->dyn);
  ws->dyn = 0;
  ws->ncap = 0;
#else
  (void) ws;
#endif
}

/* The larger of m and a, NaN if either is: a maximum taken over components with it is NaN
 * if any of them is. */
static casadi_real nan_max(casadi_real m, casadi_real a) {
  return isnan(m) || a <= m ? m : a;
}

/* max |x_i| (NaN if some x_i is). */
static casadi_real norm_inf(const casadi_real *x, int n) {
  casadi_real m = 0;
  int i;
  for (i = 0; i < n; ++i) m = nan_max(m, fabs(x[i]));
  return m;
}

static int all_finite(const casadi_real *x, int n) {
  int i;
  for (i = 0; i < n; ++i)
    if (!isfinite(x[i])) return 0;
  return 1;
}

/* x = K^-1 r by the generated sparse QR. */
static int solve(workspace *ws, const casadi_real *K, const casadi_real *r, casadi_real *x) {
  ws->arg[0] = K;
  ws->arg[1] = r;
  ws->res[0] = x;
  return KERNEL_SOLVE(ws->arg, ws->res, ws->iw, ws->w, 0);
}

/* P = dE/dt at (t, q, v, lam, u) (KERNEL_POWER) and its parts into P[0 .. NPOWER - 1]
 * (WORK_TOTAL .. WORK_DRIVES). */
static int power(workspace *ws, casadi_real t, const casadi_real *q, const casadi_real *v, const casadi_real *lam,
                 const casadi_real *u, const casadi_real *p, casadi_real *P) {
  ws->arg[0] = &t;
  ws->arg[1] = q;
  ws->arg[2] = v;
  ws->arg[3] = lam;
  ws->arg[4] = u;
  ws->arg[5] = p;
  ws->res[0] = P;
  return KERNEL_POWER(ws->arg, ws->res, ws->iw, ws->w, 0) ? STEP_KERNEL : STEP_OK;
}

/* The step on a laid-out workspace (see <model>_step; h may be negative here, a backward
 * step of a composition).  Newton starts from ws->x if `warm`, else from [v; 0].  On
 * success ws->x holds [w; h/2 lambda], ws->dx [v+; h/2 mu], and with ws->track_work
 * ws->step_work the step's work. */
static int step(const casadi_real *q, const casadi_real *v, casadi_real t, const casadi_real *u,
                const casadi_real *p, casadi_real h, casadi_real *q_next, casadi_real *v_next,
                casadi_real *lam, int *iterations, const step_options *o, int warm,
                workspace *ws) {
  casadi_real t1 = t + h, tol = o->tol;
  int i, it;
  if (iterations) *iterations = 0;
  if (!(h != 0) || !isfinite(t1) || !(tol > 0) || o->max_iter < 1 || o->max_halvings < 0 ||
      o->max_halvings > MAX_HALVINGS || o->scheme < 0 || o->scheme > SCHEME_RATTLE4)
    return STEP_BAD_INPUT;
#ifdef NCGEN_CONTACTS
  if (o->scheme != 0) return STEP_BAD_INPUT; /* contacts keep their own scheme */
#endif

  /* First half-step: Newton on x = [w; h/2 lambda]. */
  if (!warm) {
    memcpy(ws->x, v, NQ * sizeof *v);
    for (i = NQ; i < NX; ++i) ws->x[i] = 0;
  }
  for (it = 0;; ++it) {
    ws->arg[0] = &t;
    ws->arg[1] = q;
    ws->arg[2] = v;
    ws->arg[3] = u;
    ws->arg[4] = p;
    ws->arg[5] = &h;
    ws->arg[6] = ws->x;
    ws->arg[7] = ws->x + NQ;
#ifdef NCGEN_CONTACTS
    ws->arg[8] = ws->j0;
#endif
    ws->res[0] = ws->r;
    ws->res[1] = ws->K;
    if (KERNEL_NEWTON(ws->arg, ws->res, ws->iw, ws->w, 0)) return STEP_KERNEL;
    {
      casadi_real e_mom = norm_inf(ws->r, NQ), e_pos = fabs(h) * norm_inf(ws->r + NQ, NC);
      if (!isfinite(e_mom) || !isfinite(e_pos)) return STEP_NOT_FINITE;
      if (e_pos <= tol && e_mom <= tol * MASS_SCALE * (1 + norm_inf(ws->x, NQ))
#ifdef NCGEN_CONTACTS
          && (it > 0 || !ws->newton_once)
#endif
      )
        break;
    }
    if (it == o->max_iter) {
      if (iterations) *iterations = it;
      return STEP_NO_CONVERGENCE;
    }
    if (solve(ws, ws->K, ws->r, ws->dx)) return STEP_KERNEL;
    if (!all_finite(ws->dx, NX)) return STEP_NOT_FINITE;
    for (i = 0; i < NX; ++i) ws->x[i] -= ws->dx[i];
  }
  if (iterations) *iterations = it;
  for (i = 0; i < NQ; ++i) q_next[i] = q[i] + h * ws->x[i];

  /* Second half-step: [[M, A^T], [A, 0]] [v+; h/2 mu] = [M w + h/2 F; -Phi_t]. */
  ws->arg[0] = &t1;
  ws->arg[1] = q_next;
  ws->arg[2] = ws->x;
  ws->arg[3] = u;
  ws->arg[4] = p;
  ws->arg[5] = &h;
#ifdef NCGEN_CONTACTS
  ws->arg[6] = ws->j;
#endif
  ws->res[0] = ws->r;
  ws->res[1] = ws->K;
  if (KERNEL_VELOCITY(ws->arg, ws->res, ws->iw, ws->w, 0)) return STEP_KERNEL;
  if (solve(ws, ws->K, ws->r, ws->dx)) return STEP_KERNEL;
  if (!all_finite(ws->dx, NX)) return STEP_NOT_FINITE;
  memcpy(v_next, ws->dx, NQ * sizeof *v_next);
  if (lam)
    for (i = 0; i < NC; ++i) lam[i] = 2 * ws->dx[NQ + i] / h;

  /* Both constraint levels at t + h. */
  ws->arg[0] = &t1;
  ws->arg[1] = q_next;
  ws->arg[2] = v_next;
  ws->arg[3] = p;
  ws->res[0] = ws->chk;
  ws->res[1] = ws->chk + 1;
  if (KERNEL_CHECK(ws->arg, ws->res, ws->iw, ws->w, 0)) return STEP_KERNEL;
  if (!(ws->chk[0] <= tol)) return STEP_NO_CONVERGENCE;
  if (!(ws->chk[1] <= tol * (1 + norm_inf(v_next, NQ)))) return STEP_VELOCITY;
  if (ws->track_work) {
    /* lambda and mu are each within O(h) of the exact multiplier, with errors of opposite
     * sign: the trapezoidal rule pairing each end with its own keeps the work second order */
    casadi_real P0[NPOWER], P1[NPOWER];
    for (i = 0; i < NC; ++i) {
      ws->lam2[i] = 2 * ws->x[NQ + i] / h;
      ws->lam2[NC + i] = 2 * ws->dx[NQ + i] / h;
    }
    if (power(ws, t, q, v, ws->lam2, u, p, P0) != STEP_OK ||
        power(ws, t1, q_next, v_next, ws->lam2 + NC, u, p, P1) != STEP_OK)
      return STEP_KERNEL;
    ws->step_work[WORK_DAMPERS] = ws->step_work[WORK_PUSH_OUT] = 0;
    for (i = 0; i < NPOWER; ++i) {
      ws->step_work[i] = h / 2 * (P0[i] + P1[i]);
      if (i > WORK_TOTAL) ws->step_work[WORK_DAMPERS] -= ws->step_work[i];
    }
    ws->step_work[WORK_DAMPERS] += ws->step_work[WORK_TOTAL];
  }
  return STEP_OK;
}

/* acc += the work by class `add` (NWORK values). */
static void work_add(casadi_real *acc, const casadi_real *add) {
  int i;
  for (i = 0; i < NWORK; ++i) acc[i] += add[i];
}

/* Warm start of the step after a successful one: w' = 2 v+ - w, h/2 lambda' = h/2 mu
 * (exact for forces independent of v when the multipliers do not change). */
static void predict(workspace *ws) {
  int i;
  for (i = 0; i < NQ; ++i) ws->x[i] = 2 * ws->dx[i] - ws->x[i];
  for (i = NQ; i < NX; ++i) ws->x[i] = ws->dx[i];
}

/* Whether the caller asked the run to stop (o->stop set and nonzero): read by the loops
 * before every step. */
static int stop_requested(const step_options *o) {
  return o->stop && *o->stop;
}

/* Newton start for a step of size h_new from rates v, after a step of size h_old that ended
 * with [w; h_old/2 lambda] in x and [v+; h_old/2 mu] in dx: w' = v + h_new/h_old (v+ - w)
 * (v+ - w = h_old/2 a), h_new/2 lambda' = h_new/h_old (h_old/2 mu).  x_new may be x. */
static void predict_scaled(casadi_real *x_new, const casadi_real *x, const casadi_real *dx, const casadi_real *v,
                           casadi_real ratio) {
  int i;
  for (i = 0; i < NQ; ++i) x_new[i] = v[i] + ratio * (dx[i] - x[i]);
  for (i = NQ; i < NX; ++i) x_new[i] = ratio * dx[i];
}

static int recoverable(int status) {
  return status == STEP_NO_CONVERGENCE || status == STEP_NOT_FINITE ||
         status == STEP_VELOCITY;
}




/* Projection of (q, v) onto both constraint levels at t in the mass metric:
 * [[M, A^T], [A, 0]] [dq; mu] = [0; Phi], q -= dq until |Phi|_inf <= tol, then the same
 * with A v + Phi_t for v (exact: the velocity constraints are linear in v). */
static int project(workspace *ws, casadi_real t, casadi_real *q, casadi_real *v, const casadi_real *p,
                   const step_options *o, casadi_real *phidot) {
  int i, it;
  for (it = 0;; ++it) {
    ws->arg[0] = &t;
    ws->arg[1] = q;
    ws->arg[2] = v;
    ws->arg[3] = p;
    ws->res[0] = ws->K;
    ws->res[1] = ws->r + NQ;
    ws->res[2] = phidot;
    if (KERNEL_PROJECT(ws->arg, ws->res, ws->iw, ws->w, 0)) return STEP_KERNEL;
    for (i = 0; i < NQ; ++i) ws->r[i] = 0;
    if (!all_finite(ws->r + NQ, NC)) return STEP_NOT_FINITE;
    if (norm_inf(ws->r + NQ, NC) <= o->tol) break;
    if (it == o->max_iter) return STEP_NO_CONVERGENCE;
    if (solve(ws, ws->K, ws->r, ws->dx)) return STEP_KERNEL;
    if (!all_finite(ws->dx, NX)) return STEP_NOT_FINITE;
    for (i = 0; i < NQ; ++i) q[i] -= ws->dx[i];
  }
  memcpy(ws->r + NQ, phidot, NC * sizeof *phidot);
  if (solve(ws, ws->K, ws->r, ws->dx)) return STEP_KERNEL;
  if (!all_finite(ws->dx, NX)) return STEP_NOT_FINITE;
  for (i = 0; i < NQ; ++i) v[i] -= ws->dx[i];
  return STEP_OK;
}
