/*
 * leaf_file.h: octmesh's leaf files, written from a p8est forest; shared by
 * the p4est reference programs (octmesh_p4est.c, octmesh_p4est_adapt.c).
 *
 * Binary (a path ending in ".bin"): "OCTLEAF1", the count as u64 LE, then
 * per leaf x, y, z, level as LE int32.  Text: "# octmesh_p4est balanced
 * leaves", "# count N", on a brick "# brick NX NY NZ", then one
 * "x y z level" line per leaf ("tree x y z level" on a brick).
 * Coordinates are tree-relative, the root side P8EST_ROOT_LEN = 2^19.
 */
#ifndef OCTMESH_LEAF_FILE_H
#define OCTMESH_LEAF_FILE_H

#include <stdint.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>

#include <mpi.h>
#include <p8est.h>

#define BIN_MAGIC "OCTLEAF1"

/* Explicit little-endian coding keeps the files portable across hosts. */
static void
put_le32 (unsigned char *p, uint32_t v)
{
  p[0] = (unsigned char) v;
  p[1] = (unsigned char) (v >> 8);
  p[2] = (unsigned char) (v >> 16);
  p[3] = (unsigned char) (v >> 24);
}

static void
put_le64 (unsigned char *p, uint64_t v)
{
  put_le32 (p, (uint32_t) v);
  put_le32 (p + 4, (uint32_t) (v >> 32));
}

static int
ends_with (const char *s, const char *suffix)
{
  size_t              ls = strlen (s), lx = strlen (suffix);
  return ls >= lx && strcmp (s + ls - lx, suffix) == 0;
}

/* Writes v in decimal at p (printf is several times slower for millions
 * of lines); returns the end. */
static char        *
fmt_int (char *p, long v)
{
  char                tmp[24];
  int                 k = 0;
  if (v < 0) {
    *p++ = '-';
    v = -v;
  }
  do {
    tmp[k++] = (char) ('0' + v % 10);
    v /= 10;
  } while (v);
  while (k)
    *p++ = tmp[--k];
  return p;
}

/* Appends this rank's leaves to f through a 1 MiB buffer; brick != 0 puts
 * the tree first on text lines.  Returns 0, or -1 on a failed write. */
static int
leaf_file_write_local (FILE * f, p8est_t * p8est, int binary, int brick)
{
  size_t              i, used = 0;
  const size_t        bufsize = 1 << 20;
  char               *buf = malloc (bufsize);
  p4est_topidx_t      tt;

  if (buf == NULL)
    return -1;
  for (tt = p8est->first_local_tree; tt <= p8est->last_local_tree; ++tt) {
    sc_array_t         *qs = &p8est_tree_array_index (p8est->trees, tt)->quadrants;
    for (i = 0; i < qs->elem_count; ++i) {
      const p8est_quadrant_t *q = p8est_quadrant_array_index (qs, i);
      if (used + 64 > bufsize) {
        if (fwrite (buf, 1, used, f) != used) {
          free (buf);
          return -1;
        }
        used = 0;
      }
      if (binary) {
        unsigned char      *p = (unsigned char *) buf + used;
        put_le32 (p, (uint32_t) q->x);
        put_le32 (p + 4, (uint32_t) q->y);
        put_le32 (p + 8, (uint32_t) q->z);
        put_le32 (p + 12, (uint32_t) q->level);
        used += 16;
      }
      else {
        char               *p = buf + used;
        if (brick) {
          p = fmt_int (p, (long) tt);
          *p++ = ' ';
        }
        p = fmt_int (p, q->x);
        *p++ = ' ';
        p = fmt_int (p, q->y);
        *p++ = ' ';
        p = fmt_int (p, q->z);
        *p++ = ' ';
        p = fmt_int (p, q->level);
        *p++ = '\n';
        used = (size_t) (p - buf);
      }
    }
  }
  if (used > 0 && fwrite (buf, 1, used, f) != used) {
    free (buf);
    return -1;
  }
  free (buf);
  return 0;
}

/* Writes the forest's leaves to path, the ranks appending in rank order
 * (the global order of the forest); brick is NULL or {0, 0, 0} for the unit
 * cube, else the brick's NX, NY, NZ (text files only).  Collective; returns
 * nonzero on every rank when any rank failed. */
static int
leaf_file_write (MPI_Comm comm, p8est_t * p8est, const char *path,
                 const int *brick)
{
  int                 binary = ends_with (path, ".bin");
  int                 on_brick = brick != NULL && brick[0] != 0;
  int                 rank, size, r, bad = 0, anybad;

  MPI_Comm_rank (comm, &rank);
  MPI_Comm_size (comm, &size);
  for (r = 0; r < size; ++r) {
    if (r == rank) {
      FILE               *f = fopen (path, r == 0 ? "wb" : "ab");
      if (f == NULL)
        bad = 1;
      else {
        if (r == 0) {
          long long           n = (long long) p8est->global_num_quadrants;
          if (binary) {
            unsigned char       hdr[16];
            memcpy (hdr, BIN_MAGIC, 8);
            put_le64 (hdr + 8, (uint64_t) n);
            bad |= fwrite (hdr, 1, 16, f) != 16;
          }
          else {
            bad |= fprintf (f, "# octmesh_p4est balanced leaves\n"
                            "# count %lld\n", n) < 0;
            if (on_brick)
              bad |= fprintf (f, "# brick %d %d %d\n", brick[0], brick[1],
                              brick[2]) < 0;
          }
        }
        bad |= leaf_file_write_local (f, p8est, binary, on_brick) != 0;
        bad |= fclose (f) != 0;
      }
    }
    MPI_Barrier (comm);
  }
  MPI_Allreduce (&bad, &anybad, 1, MPI_INT, MPI_MAX, comm);
  return anybad;
}

#endif
