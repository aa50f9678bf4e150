/*
 * octmesh_p4est: rebuild an octmesh leaf file as a p8est forest, 2:1-balance
 * it with p4est and report counts and timings.  Serves as the independent
 * reference and benchmark baseline for octmesh.
 *
 * Usage: mpirun -np P octmesh_p4est --in LEAVES --balance face|edge|corner|none
 *          [--out LEAVES_OUT] [--nodes] [--lnodes-only] [--json FILE]
 *          [--repeat K]
 *
 * --nodes times p8est_ghost_new, then p8est_lnodes_new (degree 1), then
 * p8est_nodes_new (corner balance only); --lnodes-only leaves out
 * p8est_nodes_new.  Memory (maximum over ranks, bytes): the peak RSS after
 * MPI and p4est start, after the leaf file is read (every rank holds the
 * whole list, which the refine callback searches), after p8est_lnodes_new
 * and after p8est_nodes_new in the first repeat, and at the end.
 *
 * Leaf files: text "x y z level" lines ('#' comments) or binary (.bin):
 * "OCTLEAF1", u64 LE count, count * 4 LE int32 (x, y, z, level).
 * Coordinates are in units where the root has side P8EST_ROOT_LEN = 2^19.
 *
 * Forests of a brick (text only): a "# brick NX NY NZ" line, then
 * "tree x y z level" lines, tree-relative coordinates.  The forest is then
 * built on p8est_connectivity_new_brick (NX, NY, NZ, 0, 0, 0) and written
 * back in the same form.
 */

#include <errno.h>
#include <stdint.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <sys/resource.h>
#include <sys/types.h>

#include <mpi.h>
#include <p8est.h>
#include <p8est_bits.h>
#include <p8est_extended.h>
#include <p8est_ghost.h>
#include <p8est_lnodes.h>
#include <p8est_nodes.h>

#include "leaf_file.h"

/* Gathering hanging nodes to rank 0 does not scale; skip beyond this. */
#define DEDUP_MAX_LEAVES 5000000LL

typedef struct
{
  int32_t             x, y, z, level;
  int32_t             tree;
}
leaf_t;

typedef struct
{
  leaf_t             *a;
  size_t              n, cap;
}
leaf_vec_t;

enum
{
  PH_REFINE, PH_BALANCE, PH_PARTITION, PH_GHOST, PH_NODES, PH_LNODES, PH_NUM
};
static const char *phase_names[PH_NUM] = {
  "refine", "balance", "partition", "ghost", "nodes", "lnodes"
};

static int          g_rank, g_size;
static int          g_brick[3] = { 0, 0, 0 };   /* 0: the unit cube */
static const leaf_t *g_leaves;  /* sorted input leaves, used by refine_fn */
static size_t       g_nleaves;

static void
finish (int code)
{
  sc_finalize ();
  MPI_Finalize ();
  exit (code);
}

static void
usage_error (const char *msg)
{
  if (g_rank == 0) {
    if (msg != NULL)
      fprintf (stderr, "octmesh_p4est: %s\n", msg);
    fprintf (stderr,
             "usage: octmesh_p4est --in LEAVES --balance face|edge|corner|none"
             " [--out LEAVES_OUT] [--nodes] [--lnodes-only] [--json FILE]"
             " [--repeat K]\n");
  }
  finish (1);
}

static void
leaf_to_quad (const leaf_t * l, p8est_quadrant_t * q)
{
  q->x = l->x;
  q->y = l->y;
  q->z = l->z;
  q->level = (int8_t) l->level;
}

static int
vec_push (leaf_vec_t * v, const leaf_t * l)
{
  if (v->n == v->cap) {
    size_t              cap = v->cap ? 2 * v->cap : 1 << 16;
    leaf_t             *a = realloc (v->a, cap * sizeof (leaf_t));
    if (a == NULL)
      return -1;
    v->a = a;
    v->cap = cap;
  }
  v->a[v->n++] = *l;
  return 0;
}

/* Explicit little-endian coding keeps the files portable across hosts. */
static uint32_t
get_le32 (const unsigned char *p)
{
  return (uint32_t) p[0] | (uint32_t) p[1] << 8 |
    (uint32_t) p[2] << 16 | (uint32_t) p[3] << 24;
}

static uint64_t
get_le64 (const unsigned char *p)
{
  return (uint64_t) get_le32 (p) | (uint64_t) get_le32 (p + 4) << 32;
}

static int
read_binary (FILE * f, const char *path, leaf_vec_t * v, char *err,
             size_t errlen)
{
  unsigned char       hdr[16];
  unsigned char      *buf;
  uint64_t            n, done = 0;
  off_t               size;
  const size_t        chunk = 1 << 16;

  if (fread (hdr, 1, 16, f) != 16 || memcmp (hdr, BIN_MAGIC, 8) != 0) {
    snprintf (err, errlen, "%s: missing OCTLEAF1 header", path);
    return -1;
  }
  n = get_le64 (hdr + 8);
  if (fseeko (f, 0, SEEK_END) != 0 || (size = ftello (f)) < 0 ||
      fseeko (f, 16, SEEK_SET) != 0) {
    snprintf (err, errlen, "%s: cannot determine file size", path);
    return -1;
  }
  if ((uint64_t) size != 16 + 16 * n) {
    snprintf (err, errlen, "%s: header count %llu does not match file size"
              " %lld", path, (unsigned long long) n, (long long) size);
    return -1;
  }
  v->a = malloc ((n ? n : 1) * sizeof (leaf_t));
  buf = malloc (chunk * 16);
  if (v->a == NULL || buf == NULL) {
    free (buf);
    snprintf (err, errlen, "%s: out of memory for %llu leaves", path,
              (unsigned long long) n);
    return -1;
  }
  v->cap = n;
  while (done < n) {
    size_t              m = (n - done < chunk) ? (size_t) (n - done) : chunk;
    size_t              i;
    if (fread (buf, 16, m, f) != m) {
      free (buf);
      snprintf (err, errlen, "%s: short read", path);
      return -1;
    }
    for (i = 0; i < m; ++i) {
      leaf_t             *l = &v->a[done + i];
      const unsigned char *p = buf + 16 * i;
      l->x = (int32_t) get_le32 (p);
      l->y = (int32_t) get_le32 (p + 4);
      l->z = (int32_t) get_le32 (p + 8);
      l->level = (int32_t) get_le32 (p + 12);
      l->tree = 0;
    }
    done += m;
  }
  v->n = n;
  free (buf);
  return 0;
}

static int
read_text (FILE * f, const char *path, leaf_vec_t * v, char *err,
           size_t errlen)
{
  char                line[1024];
  long long           lineno = 0;

  while (fgets (line, sizeof line, f) != NULL) {
    char               *p = line, *end;
    long                val[5];
    int                 k, nf, o;
    leaf_t              l;

    ++lineno;
    while (*p == ' ' || *p == '\t' || *p == '\r' || *p == '\n')
      ++p;
    if (strchr (line, '\n') == NULL && !feof (f)) {
      int                 c;
      if (*p != '#') {
        snprintf (err, errlen, "%s:%lld: line too long", path, lineno);
        return -1;
      }
      /* Long comment: drop the rest of the line. */
      while ((c = fgetc (f)) != EOF && c != '\n');
      continue;
    }
    if (!strncmp (p, "# brick ", 8)) {
      if (sscanf (p + 8, "%d %d %d", &g_brick[0], &g_brick[1], &g_brick[2])
          != 3 || g_brick[0] < 1 || g_brick[1] < 1 || g_brick[2] < 1) {
        snprintf (err, errlen, "%s:%lld: bad brick line", path, lineno);
        return -1;
      }
      continue;
    }
    if (*p == '\0' || *p == '#')
      continue;
    nf = g_brick[0] ? 5 : 4;
    for (k = 0; k < nf; ++k) {
      errno = 0;
      val[k] = strtol (p, &end, 10);
      if (end == p || errno != 0 || val[k] < INT32_MIN || val[k] > INT32_MAX) {
        snprintf (err, errlen, "%s:%lld: expected %d integers", path, lineno,
                  nf);
        return -1;
      }
      p = end;
    }
    while (*p == ' ' || *p == '\t' || *p == '\r' || *p == '\n')
      ++p;
    if (*p != '\0') {
      snprintf (err, errlen, "%s:%lld: trailing characters", path, lineno);
      return -1;
    }
    o = nf - 4;
    l.tree = o ? (int32_t) val[0] : 0;
    l.x = (int32_t) val[o];
    l.y = (int32_t) val[o + 1];
    l.z = (int32_t) val[o + 2];
    l.level = (int32_t) val[o + 3];
    if (vec_push (v, &l) != 0) {
      snprintf (err, errlen, "%s: out of memory", path);
      return -1;
    }
  }
  if (ferror (f)) {
    snprintf (err, errlen, "%s: read error", path);
    return -1;
  }
  return 0;
}

static int
read_leaves (const char *path, leaf_vec_t * v, char *err, size_t errlen)
{
  FILE               *f = fopen (path, "rb");
  char                magic[8];
  int                 ret, is_bin;

  if (f == NULL) {
    snprintf (err, errlen, "%s: %s", path, strerror (errno));
    return -1;
  }
  /* Detect by content so a binary file with another name still works. */
  is_bin = fread (magic, 1, 8, f) == 8 && memcmp (magic, BIN_MAGIC, 8) == 0;
  rewind (f);
  if (is_bin || ends_with (path, ".bin"))
    ret = read_binary (f, path, v, err, errlen);
  else
    ret = read_text (f, path, v, err, errlen);
  fclose (f);
  return ret;
}

/* Checks order, levels, alignment, no overlap and full coverage of the root. */
static int
validate_leaves (const leaf_vec_t * v, int *minlevel, char *err,
                 size_t errlen)
{
  size_t              i;
  uint64_t            volume = 0;
  long long           ntrees = g_brick[0] ? (long long) g_brick[0] * g_brick[1]
    * g_brick[2] : 1;
  p8est_quadrant_t    prev, cur;

  memset (&prev, 0, sizeof prev);
  memset (&cur, 0, sizeof cur);
  *minlevel = P8EST_QMAXLEVEL;
  if (v->n == 0) {
    snprintf (err, errlen, "leaf file is empty");
    return -1;
  }
  for (i = 0; i < v->n; ++i) {
    const leaf_t       *l = &v->a[i];
    p4est_qcoord_t      len;

    if (l->level < 0 || l->level > P8EST_QMAXLEVEL) {
      snprintf (err, errlen, "leaf %zu: level %d outside [0, %d]", i,
                l->level, P8EST_QMAXLEVEL);
      return -1;
    }
    len = P8EST_QUADRANT_LEN (l->level);
    if (l->x < 0 || l->y < 0 || l->z < 0 || l->x >= P8EST_ROOT_LEN ||
        l->y >= P8EST_ROOT_LEN || l->z >= P8EST_ROOT_LEN) {
      snprintf (err, errlen, "leaf %zu: coordinates (%d %d %d) outside"
                " [0, %d)", i, l->x, l->y, l->z, (int) P8EST_ROOT_LEN);
      return -1;
    }
    if ((l->x & (len - 1)) || (l->y & (len - 1)) || (l->z & (len - 1))) {
      snprintf (err, errlen, "leaf %zu: (%d %d %d) not aligned to level %d",
                i, l->x, l->y, l->z, l->level);
      return -1;
    }
    if (l->tree < 0 || l->tree >= ntrees) {
      snprintf (err, errlen, "leaf %zu: tree %d outside [0, %lld)", i, l->tree,
                ntrees);
      return -1;
    }
    leaf_to_quad (l, &cur);
    if (i > 0 && l->tree < v->a[i - 1].tree) {
      snprintf (err, errlen, "leaf %zu: trees not in increasing order", i);
      return -1;
    }
    if (i > 0 && l->tree == v->a[i - 1].tree) {
      if (p8est_quadrant_compare (&prev, &cur) >= 0) {
        snprintf (err, errlen, "leaf %zu: not strictly increasing in Morton"
                  " order", i);
        return -1;
      }
      /* In sorted order any overlap shows up between neighbours. */
      if (p8est_quadrant_is_ancestor (&prev, &cur)) {
        snprintf (err, errlen, "leaf %zu: overlaps its predecessor", i);
        return -1;
      }
    }
    if (l->level < *minlevel)
      *minlevel = l->level;
    volume += (uint64_t) 1 << (3 * (P8EST_MAXLEVEL - l->level));
    prev = cur;
  }
  if (volume != (uint64_t) ntrees << (3 * P8EST_MAXLEVEL)) {
    snprintf (err, errlen, "leaves do not cover the root cube or brick");
    return -1;
  }
  return 0;
}

/* Refine iff q is a strict ancestor of some leaf: the first leaf not
 * before q in Morton order is then a descendant of q. */
static int
refine_fn (p8est_t * p8est, p4est_topidx_t which_tree, p8est_quadrant_t * q)
{
  size_t              lo = 0, hi = g_nleaves;
  p8est_quadrant_t    t;

  (void) p8est;
  memset (&t, 0, sizeof t);
  while (lo < hi) {
    size_t              mid = lo + (hi - lo) / 2;
    leaf_to_quad (&g_leaves[mid], &t);
    if (g_leaves[mid].tree < which_tree || (g_leaves[mid].tree == which_tree
                                            && p8est_quadrant_compare (&t,
                                                                       q) <
                                            0))
      lo = mid + 1;
    else
      hi = mid;
  }
  if (lo == g_nleaves || g_leaves[lo].tree != which_tree)
    return 0;
  leaf_to_quad (&g_leaves[lo], &t);
  return p8est_quadrant_is_ancestor (q, &t);
}

/* Peak RSS of this process so far, bytes. */
static long long
peak_rss (void)
{
  struct rusage       ru;
  getrusage (RUSAGE_SELF, &ru);
  return (long long) ru.ru_maxrss * 1024;
}

static long long
max_over_ranks (MPI_Comm comm, long long v)
{
  long long           m;
  MPI_Allreduce (&v, &m, 1, MPI_LONG_LONG, MPI_MAX, comm);
  return m;
}

static double
phase_begin (MPI_Comm comm)
{
  MPI_Barrier (comm);
  return MPI_Wtime ();
}

static double
phase_end (MPI_Comm comm, double t0)
{
  double              dt = MPI_Wtime () - t0, mx;
  MPI_Allreduce (&dt, &mx, 1, MPI_DOUBLE, MPI_MAX, comm);
  return mx;
}

static int
cmp_double (const void *a, const void *b)
{
  double              x = *(const double *) a, y = *(const double *) b;
  return (x > y) - (x < y);
}

static double
median (const double *v, int k)
{
  double             *s = malloc (k * sizeof (double)), m;
  memcpy (s, v, k * sizeof (double));
  qsort (s, k, sizeof (double), cmp_double);
  m = (k % 2) ? s[k / 2] : 0.5 * (s[k / 2 - 1] + s[k / 2]);
  free (s);
  return m;
}

static int
cmp_xyz (const void *a, const void *b)
{
  const int32_t      *p = a, *q = b;
  int                 i;
  for (i = 0; i < 4; ++i)
    if (p[i] != q[i])
      return (p[i] > q[i]) - (p[i] < q[i]);
  return 0;
}

/* Hanging nodes are stored per process and repeat across process
 * boundaries, so count unique (tree, coordinates) on rank 0.  The tree
 * matters in a brick, where coordinates are tree-relative; p4est stores a
 * node on a tree boundary in one canonical tree. */
static long long
count_unique_nodes (MPI_Comm comm, sc_array_t * arr)
{
  int                 nloc = (int) arr->elem_count, i;
  int32_t            *loc = malloc ((4 * (size_t) nloc + 1) * sizeof (int32_t));
  int                *counts = NULL, *displs = NULL;
  int32_t            *all = NULL;
  long long           total = 0, uniq = 0;

  for (i = 0; i < nloc; ++i) {
    /* p8est_hang4_t and p8est_hang2_t both begin with x, y, z, level and
     * then the tree. */
    const p8est_hang4_t *h = (const p8est_hang4_t *) sc_array_index (arr, i);
    loc[4 * i] = h->p.which_tree;
    loc[4 * i + 1] = h->x;
    loc[4 * i + 2] = h->y;
    loc[4 * i + 3] = h->z;
  }
  if (g_rank == 0) {
    counts = malloc (g_size * sizeof (int));
    displs = malloc (g_size * sizeof (int));
  }
  nloc *= 4;
  MPI_Gather (&nloc, 1, MPI_INT, counts, 1, MPI_INT, 0, comm);
  if (g_rank == 0) {
    for (i = 0; i < g_size; ++i) {
      displs[i] = (int) total;
      total += counts[i];
    }
    all = malloc ((total + 1) * sizeof (int32_t));
  }
  MPI_Gatherv (loc, nloc, MPI_INT32_T, all, counts, displs, MPI_INT32_T, 0,
               comm);
  if (g_rank == 0) {
    long long           m = total / 4, j;
    qsort (all, (size_t) m, 4 * sizeof (int32_t), cmp_xyz);
    for (j = 0; j < m; ++j)
      if (j == 0 || cmp_xyz (all + 4 * j, all + 4 * (j - 1)) != 0)
        ++uniq;
  }
  free (loc);
  free (all);
  free (counts);
  free (displs);
  MPI_Bcast (&uniq, 1, MPI_LONG_LONG, 0, comm);
  return uniq;
}

/* Ranks append in rank order; a partitioned single-tree forest is then
 * in global Morton order. */
static void
write_leaves (MPI_Comm comm, p8est_t * p8est, const char *path)
{
  if (leaf_file_write (comm, p8est, path, g_brick)) {
    if (g_rank == 0)
      fprintf (stderr, "octmesh_p4est: failed writing %s\n", path);
    finish (1);
  }
}

int
main (int argc, char **argv)
{
  MPI_Comm            comm = MPI_COMM_WORLD;
  const char         *in = NULL, *out = NULL, *json = NULL, *bal = NULL;
  int                 want_nodes = 0, lnodes_only = 0, repeat = 1;
  int                 minlevel = 0, i, rep, ph;
  int                 do_balance, do_nodes = 0, do_lnodes = 0;
  p8est_connect_type_t btype = P8EST_CONNECT_FULL;
  leaf_vec_t          leaves = { NULL, 0, 0 };
  char                err[512] = "";
  int                 bad, anybad;
  double             *times[PH_NUM];
  int                 have_time[PH_NUM] = { 0 };
  p8est_connectivity_t *conn;
  p8est_t            *p8est = NULL;
  long long           n_bal = 0, indep = -1, face_hang = -1, edge_hang = -1;
  long long           ln_global = -1, ln_hang = -1;
  int                 dedup_skipped = 0;
  long long           max_rss, rss_start, rss_read;
  long long           rss_lnodes = -1, rss_nodes = -1;

  MPI_Init (&argc, &argv);
  MPI_Comm_rank (comm, &g_rank);
  MPI_Comm_size (comm, &g_size);
  sc_init (comm, 1, 1, NULL, SC_LP_ESSENTIAL);
  p4est_init (NULL, SC_LP_ESSENTIAL);
  rss_start = max_over_ranks (comm, peak_rss ());

  for (i = 1; i < argc; ++i) {
    const char         *a = argv[i];
    int                 has_val = i + 1 < argc;
    if (!strcmp (a, "--in") && has_val)
      in = argv[++i];
    else if (!strcmp (a, "--out") && has_val)
      out = argv[++i];
    else if (!strcmp (a, "--json") && has_val)
      json = argv[++i];
    else if (!strcmp (a, "--balance") && has_val)
      bal = argv[++i];
    else if (!strcmp (a, "--repeat") && has_val) {
      char               *end;
      long                k = strtol (argv[++i], &end, 10);
      if (*end != '\0' || k < 1 || k > 100000)
        usage_error ("--repeat needs a positive integer");
      repeat = (int) k;
    }
    else if (!strcmp (a, "--nodes"))
      want_nodes = 1;
    else if (!strcmp (a, "--lnodes-only"))
      lnodes_only = 1;
    else if (!strcmp (a, "--help") || !strcmp (a, "-h"))
      usage_error (NULL);
    else {
      snprintf (err, sizeof err, "unknown or incomplete argument '%s'", a);
      usage_error (err);
    }
  }
  if (in == NULL || bal == NULL)
    usage_error ("--in and --balance are required");
  do_balance = 1;
  if (!strcmp (bal, "face"))
    btype = P8EST_CONNECT_FACE;
  else if (!strcmp (bal, "edge"))
    btype = P8EST_CONNECT_EDGE;
  else if (!strcmp (bal, "corner"))
    btype = P8EST_CONNECT_FULL;
  else if (!strcmp (bal, "none"))
    do_balance = 0;
  else
    usage_error ("--balance must be face, edge, corner or none");
  if (want_nodes) {
    /* p4est does not check these preconditions in release builds. */
    if (!do_balance || btype == P8EST_CONNECT_FACE)
      usage_error ("--nodes needs --balance edge (lnodes) or corner"
                   " (nodes and lnodes)");
    do_lnodes = 1;
    do_nodes = btype == P8EST_CONNECT_FULL && !lnodes_only;
  }
  else if (lnodes_only)
    usage_error ("--lnodes-only needs --nodes");

  bad = read_leaves (in, &leaves, err, sizeof err) != 0;
  if (!bad)
    bad = validate_leaves (&leaves, &minlevel, err, sizeof err) != 0;
  MPI_Allreduce (&bad, &anybad, 1, MPI_INT, MPI_MAX, comm);
  if (anybad) {
    if (g_rank == 0)
      fprintf (stderr, "octmesh_p4est: %s\n",
               bad ? err : "input error on another rank");
    free (leaves.a);
    finish (1);
  }
  g_leaves = leaves.a;
  g_nleaves = leaves.n;
  rss_read = max_over_ranks (comm, peak_rss ());

  for (ph = 0; ph < PH_NUM; ++ph)
    times[ph] = calloc (repeat, sizeof (double));
  have_time[PH_REFINE] = have_time[PH_PARTITION] = 1;
  have_time[PH_BALANCE] = do_balance;
  have_time[PH_GHOST] = do_nodes || do_lnodes;
  have_time[PH_NODES] = do_nodes;
  have_time[PH_LNODES] = do_lnodes;

  if (g_brick[0] && ends_with (out ? out : "", ".bin"))
    usage_error ("brick forests are written as text only");
  conn = g_brick[0] ? p8est_connectivity_new_brick (g_brick[0], g_brick[1],
                                                    g_brick[2], 0, 0, 0)
    : p8est_connectivity_new_unitcube ();
  for (rep = 0; rep < repeat; ++rep) {
    int                 last = rep == repeat - 1;
    double              t0;
    p8est_ghost_t      *ghost = NULL;

    t0 = phase_begin (comm);
    p8est = p8est_new_ext (comm, conn, 0, minlevel, 1, 0, NULL, NULL);
    p8est_refine (p8est, 1, refine_fn, NULL);
    p8est_partition (p8est, 0, NULL);
    times[PH_REFINE][rep] = phase_end (comm, t0);
    if ((unsigned long long) p8est->global_num_quadrants != leaves.n) {
      if (g_rank == 0)
        fprintf (stderr, "octmesh_p4est: rebuilt forest has %lld leaves,"
                 " file has %zu\n",
                 (long long) p8est->global_num_quadrants, leaves.n);
      p8est_destroy (p8est);
      p8est_connectivity_destroy (conn);
      free (leaves.a);
      finish (1);
    }

    if (do_balance) {
      t0 = phase_begin (comm);
      p8est_balance (p8est, btype, NULL);
      times[PH_BALANCE][rep] = phase_end (comm, t0);
    }
    t0 = phase_begin (comm);
    p8est_partition (p8est, 0, NULL);
    times[PH_PARTITION][rep] = phase_end (comm, t0);
    n_bal = (long long) p8est->global_num_quadrants;

    if (do_nodes || do_lnodes) {
      t0 = phase_begin (comm);
      ghost = p8est_ghost_new (p8est, P8EST_CONNECT_FULL);
      times[PH_GHOST][rep] = phase_end (comm, t0);
    }
    if (do_lnodes) {
      p8est_lnodes_t     *ln;
      t0 = phase_begin (comm);
      ln = p8est_lnodes_new (p8est, ghost, 1);
      times[PH_LNODES][rep] = phase_end (comm, t0);
      /* Before p8est_nodes_new runs: the peak of the lnodes pipeline. */
      if (rep == 0)
        rss_lnodes = max_over_ranks (comm, peak_rss ());
      if (last) {
        long long           own = ln->owned_count, hang = 0;
        p4est_locidx_t      e;
        for (e = 0; e < ln->num_local_elements; ++e)
          hang += ln->face_code[e] != 0;
        MPI_Allreduce (&own, &ln_global, 1, MPI_LONG_LONG, MPI_SUM, comm);
        MPI_Allreduce (&hang, &ln_hang, 1, MPI_LONG_LONG, MPI_SUM, comm);
      }
      p8est_lnodes_destroy (ln);
    }
    if (do_nodes) {
      p8est_nodes_t      *nodes;
      t0 = phase_begin (comm);
      nodes = p8est_nodes_new (p8est, ghost);
      times[PH_NODES][rep] = phase_end (comm, t0);
      /* Before the hanging-node census, which gathers on rank 0. */
      if (rep == 0)
        rss_nodes = max_over_ranks (comm, peak_rss ());
      if (last) {
        long long           own = nodes->num_owned_indeps;
        MPI_Allreduce (&own, &indep, 1, MPI_LONG_LONG, MPI_SUM, comm);
        if (n_bal > DEDUP_MAX_LEAVES)
          dedup_skipped = 1;
        else {
          face_hang = count_unique_nodes (comm, &nodes->face_hangings);
          edge_hang = count_unique_nodes (comm, &nodes->edge_hangings);
        }
      }
      p8est_nodes_destroy (nodes);
    }
    if (ghost != NULL)
      p8est_ghost_destroy (ghost);
    if (!last) {
      p8est_destroy (p8est);
      p8est = NULL;
    }
  }

  if (out != NULL)
    write_leaves (comm, p8est, out);

  max_rss = max_over_ranks (comm, peak_rss ());

  if (g_rank == 0) {
    double              med[PH_NUM];
    for (ph = 0; ph < PH_NUM; ++ph)
      med[ph] = have_time[ph] ? median (times[ph], repeat) : 0.0;

    printf ("octmesh_p4est (p4est %s)  ranks %d  balance %s  repeat %d\n",
            P4EST_VERSION, g_size, bal, repeat);
    printf ("  %-22s %lld\n", "leaves_in", (long long) leaves.n);
    printf ("  %-22s %lld\n", "leaves_balanced", n_bal);
    for (ph = 0; ph < PH_NUM; ++ph)
      if (have_time[ph])
        printf ("  %-22s %.6f s (median)\n", phase_names[ph], med[ph]);
    if (do_nodes) {
      printf ("  %-22s %lld\n", "indep_nodes", indep);
      printf ("  %-22s %lld\n", "face_hanging_nodes", face_hang);
      printf ("  %-22s %lld\n", "edge_hanging_nodes", edge_hang);
      if (dedup_skipped)
        printf ("  (hanging node de-duplication skipped above %lld leaves)\n",
                DEDUP_MAX_LEAVES);
    }
    if (do_lnodes) {
      printf ("  %-22s %lld\n", "lnodes_global", ln_global);
      printf ("  %-22s %lld\n", "lnodes_hanging_elements", ln_hang);
    }
    printf ("  %-22s %lld\n", "peak_rss_bytes", max_rss);
    printf ("  %-22s %lld\n", "rss_start_bytes", rss_start);
    printf ("  %-22s %lld\n", "rss_after_read_bytes", rss_read);
    if (do_lnodes)
      printf ("  %-22s %lld\n", "rss_lnodes_bytes", rss_lnodes);
    if (do_nodes)
      printf ("  %-22s %lld\n", "rss_nodes_bytes", rss_nodes);

    if (json != NULL) {
      FILE               *f = fopen (json, "w");
      int                 first = 1;
      if (f == NULL) {
        fprintf (stderr, "octmesh_p4est: cannot write %s\n", json);
        bad = 1;
      }
      else {
        fprintf (f, "{\"tool\": \"p4est\", \"version\": \"%s\", "
                 "\"ranks\": %d, \"repeat\": %d, \"leaves_in\": %lld, "
                 "\"leaves_balanced\": %lld, \"balance\": \"%s\", "
                 "\"timings\": {", P4EST_VERSION, g_size, repeat,
                 (long long) leaves.n, n_bal, bal);
        for (ph = 0; ph < PH_NUM; ++ph)
          if (have_time[ph]) {
            fprintf (f, "%s\"%s\": %.9f", first ? "" : ", ",
                     phase_names[ph], med[ph]);
            first = 0;
          }
        fprintf (f, "}");
        if (do_nodes) {
          fprintf (f, ", \"indep_nodes\": %lld", indep);
          /* Skipped de-duplication means not computed: leave keys out. */
          if (!dedup_skipped)
            fprintf (f, ", \"face_hanging_nodes\": %lld, "
                     "\"edge_hanging_nodes\": %lld", face_hang, edge_hang);
        }
        if (do_lnodes)
          fprintf (f, ", \"lnodes_global\": %lld, "
                   "\"lnodes_hanging_elements\": %lld", ln_global, ln_hang);
        fprintf (f, ", \"rss_start_bytes\": %lld, "
                 "\"rss_after_read_bytes\": %lld", rss_start, rss_read);
        if (do_lnodes)
          fprintf (f, ", \"rss_lnodes_bytes\": %lld", rss_lnodes);
        if (do_nodes)
          fprintf (f, ", \"rss_nodes_bytes\": %lld", rss_nodes);
        fprintf (f, ", \"peak_rss_bytes\": %lld}\n", max_rss);
        bad = fclose (f) != 0;
      }
    }
  }
  MPI_Bcast (&bad, 1, MPI_INT, 0, comm);

  p8est_destroy (p8est);
  p8est_connectivity_destroy (conn);
  for (ph = 0; ph < PH_NUM; ++ph)
    free (times[ph]);
  free (leaves.a);
  finish (bad ? 1 : 0);
  return 0;
}
