/*
 * ctl_vtk.c - the VTK XML writers of mpmctl (ctl_vtk.h): a snapshot as
 * PolyData (.vtp), the grid as ImageData (.vti), a run as a collection
 * (.pvd).  Every array is described once (name, type, components, where
 * its values come from and how they are laid out: padded vectors, the
 * Voigt stress as a 3x3 tensor, F padded with the identity, running
 * indices, 0/1 flags); the encoders then lay its bytes out once (or use
 * the snapshot's own array when it already has the layout) and write them
 * appended raw (a UInt64 byte count, then the bytes), appended base64 (the
 * count and the bytes as one base64 stream), zlib-compressed (the VTK
 * block header, then blocks of 1 MiB deflated at level 1 by up to four
 * threads; every array is compressed before the XML is written, since the
 * offsets come first), or
 * as ASCII text.  The XML header carries the appended offsets, computed
 * from the sizes, so the file is written in one pass.
 */
#include "ctl_vtk.h"

#include <errno.h>
#include <inttypes.h>
#include <pthread.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <unistd.h>

#include <zlib.h>

#include "ctl.h"

#if defined(__BYTE_ORDER__) && __BYTE_ORDER__ == __ORDER_BIG_ENDIAN__
#define VTK_BYTE_ORDER "BigEndian"
#else
#define VTK_BYTE_ORDER "LittleEndian"
#endif

#define ZBLOCK ((size_t)1 << 20) /* uncompressed bytes per zlib block */

typedef enum { VT_F64, VT_I64, VT_U8 } vtype;

/* Where an array's values come from. */
typedef enum {
    K_COPY,  /* src, ncomp values per tuple, as they are */
    K_PAD,   /* src with w values per tuple, padded with zeros to ncomp */
    K_VOIGT, /* src: 6 Voigt values per tuple -> 3x3 symmetric */
    K_F,     /* src: w x w row-major per tuple -> 3x3, the identity padding */
    K_IOTA,  /* the tuple's index */
    K_FLAG   /* isrc: 0/1 as UInt8 */
} vkind;

typedef struct {
    const char *name;
    vtype type;
    int ncomp;
    size_t ntuples;
    vkind kind;
    const double *src;
    const int *isrc;
    int w;
    /* filled by the encoder */
    uint8_t *bytes; /* laid out values (owned when own) */
    int own;
    size_t nbytes;
    uint8_t *z;    /* zlib: the header and the compressed blocks */
    size_t zbytes; /* their size */
} varr;

static size_t type_size(vtype t)
{
    return t == VT_U8 ? 1 : 8;
}

static const char *type_name(vtype t)
{
    return t == VT_F64 ? "Float64" : t == VT_I64 ? "Int64" : "UInt8";
}

const char *ctl_vtk_enc_name(ctl_vtk_enc enc)
{
    switch (enc) {
    case CTL_VTK_RAW: return "raw";
    case CTL_VTK_BASE64: return "base64";
    case CTL_VTK_ZLIB: return "zlib";
    default: return "ascii";
    }
}

/* The value of component c of tuple i, as a double (K_IOTA and K_FLAG
 * give integers). */
static double value_at(const varr *a, size_t i, int c)
{
    switch (a->kind) {
    case K_COPY: return a->src[i * (size_t)a->ncomp + (size_t)c];
    case K_PAD: return c < a->w ? a->src[i * (size_t)a->w + (size_t)c] : 0.0;
    case K_VOIGT: {
        /* row-major 3x3 from sxx syy szz sxy syz sxz */
        static const int map[9] = {0, 3, 5, 3, 1, 4, 5, 4, 2};
        return a->src[i * 6 + (size_t)map[c]];
    }
    case K_F: {
        int r = c / 3, k = c % 3;
        if (r < a->w && k < a->w) return a->src[i * (size_t)(a->w * a->w) + (size_t)(r * a->w + k)];
        return r == k ? 1.0 : 0.0;
    }
    case K_IOTA: return (double)i;
    default: return a->isrc[i] ? 1.0 : 0.0;
    }
}

/* Lays out the array's bytes (a->bytes, a->nbytes); a K_COPY array of
 * doubles is used in place. */
static int layout(varr *a)
{
    size_t nv = a->ntuples * (size_t)a->ncomp;
    a->nbytes = nv * type_size(a->type);
    a->own = 0;
    if (a->kind == K_COPY && a->type == VT_F64) {
        a->bytes = (uint8_t *)(uintptr_t)a->src;
        return 0;
    }
    a->bytes = malloc(a->nbytes ? a->nbytes : 1);
    if (!a->bytes) return CTL_ESYS;
    a->own = 1;
    if (a->type == VT_I64) {
        int64_t *o = (int64_t *)(void *)a->bytes;
        for (size_t i = 0; i < a->ntuples; i++) o[i] = (int64_t)i + (a->kind == K_IOTA && a->w);
    } else if (a->type == VT_U8) {
        for (size_t i = 0; i < a->ntuples; i++) a->bytes[i] = a->isrc[i] ? 1 : 0;
    } else {
        double *o = (double *)(void *)a->bytes;
        if (a->kind == K_PAD) {
            size_t w = (size_t)a->w, nc = (size_t)a->ncomp;
            for (size_t i = 0; i < a->ntuples; i++) {
                const double *s = a->src + i * w;
                double *d = o + i * nc;
                size_t c = 0;
                for (; c < w; c++) d[c] = s[c];
                for (; c < nc; c++) d[c] = 0.0;
            }
        } else {
            for (size_t i = 0; i < a->ntuples; i++)
                for (int c = 0; c < a->ncomp; c++)
                    o[i * (size_t)a->ncomp + (size_t)c] = value_at(a, i, c);
        }
    }
    return 0;
}

static void release(varr *a, size_t n)
{
    for (size_t k = 0; k < n; k++) {
        if (a[k].own) free(a[k].bytes);
        free(a[k].z);
        a[k].bytes = NULL;
        a[k].z = NULL;
        a[k].own = 0;
    }
}

/* zlib: blocks compressed by a few threads, each block into its own slot
 * of a scratch buffer; deflate level 1 with the run-length strategy: on
 * doubles as fast as Huffman alone, much faster than the default matching,
 * for a ratio within a few per cent of it (make bench-vtk measures them;
 * docs/performance.md). */
typedef struct {
    const varr *a;
    size_t nb, slot, first, stride;
    uint8_t *scratch;
    uint64_t *sizes;
    int failed;
} zjob;

static void *zwork(void *arg)
{
    zjob *j = arg;
    z_stream zs;
    memset(&zs, 0, sizeof zs);
    /* running indices compress far better with matching */
    int strategy = j->a->type == VT_I64 ? Z_DEFAULT_STRATEGY : Z_RLE;
    if (deflateInit2(&zs, Z_BEST_SPEED, Z_DEFLATED, 15, 8, strategy) != Z_OK) {
        j->failed = 1;
        return NULL;
    }
    for (size_t b = j->first; b < j->nb; b += j->stride) {
        size_t in = b + 1 < j->nb ? ZBLOCK : j->a->nbytes - b * ZBLOCK;
        zs.next_in = j->a->bytes + b * ZBLOCK;
        zs.avail_in = (uInt)in;
        zs.next_out = j->scratch + b * j->slot;
        zs.avail_out = (uInt)j->slot;
        if (deflate(&zs, Z_FINISH) != Z_STREAM_END) {
            j->failed = 1;
            break;
        }
        j->sizes[b] = zs.total_out;
        deflateReset(&zs);
    }
    deflateEnd(&zs);
    return NULL;
}

#define ZTHREADS 4

/* The VTK header (UInt64: blocks, block size, the last block's size when
 * partial, else 0, the compressed size of each) and the blocks, into a->z. */
static int compress_array(varr *a)
{
    size_t nb = (a->nbytes + ZBLOCK - 1) / ZBLOCK, hdr = (3 + nb) * 8;
    size_t slot = deflateBound(NULL, (uLong)ZBLOCK) + 64, pos = hdr;
    long ncpu = sysconf(_SC_NPROCESSORS_ONLN);
    size_t nt = ncpu < 1 ? 1 : ncpu > ZTHREADS ? ZTHREADS : (size_t)ncpu;
    pthread_t th[ZTHREADS];
    zjob jobs[ZTHREADS];
    int running[ZTHREADS] = {0};
    uint8_t *scratch;
    uint64_t *h;
    int failed = 0;
    /* each block into its slot after the header, then moved down */
    a->z = malloc(hdr + nb * slot + 1);
    if (!a->z) return CTL_ESYS;
    scratch = a->z + hdr;
    h = (uint64_t *)(void *)a->z;
    h[0] = nb;
    h[1] = ZBLOCK;
    h[2] = a->nbytes % ZBLOCK;
    if (nt > nb) nt = nb ? nb : 1;
    for (size_t t = 0; t < nt; t++) {
        jobs[t] = (zjob){.a = a,
                         .nb = nb,
                         .slot = slot,
                         .first = t,
                         .stride = nt,
                         .scratch = scratch,
                         .sizes = h + 3};
        /* share 0 is this thread's, and so is the share of a thread that
         * cannot start */
        if (t && !pthread_create(&th[t], NULL, zwork, &jobs[t])) running[t] = 1;
    }
    for (size_t t = 0; t < nt; t++)
        if (!running[t]) zwork(&jobs[t]);
    for (size_t t = 1; t < nt; t++)
        if (running[t]) pthread_join(th[t], NULL);
    for (size_t t = 0; t < nt; t++) failed |= jobs[t].failed;
    for (size_t b = 0; !failed && b < nb; b++) {
        memmove(a->z + pos, scratch + b * slot, (size_t)h[3 + b]);
        pos += (size_t)h[3 + b];
    }
    a->zbytes = pos;
    return failed ? CTL_ESYS : 0;
}

/* Bytes the array takes in the appended section. */
static size_t appended_size(const varr *a, ctl_vtk_enc enc)
{
    if (enc == CTL_VTK_ZLIB) return a->zbytes;
    if (enc == CTL_VTK_BASE64) return 4 * ((8 + a->nbytes + 2) / 3);
    return 8 + a->nbytes;
}

/* ---- base64 ------------------------------------------------------------- */

typedef struct {
    FILE *f;
    uint8_t carry[3];
    int nc;
    char out[1 << 16];
    size_t no;
} b64;

static const char b64chars[] = "ABCDEFGHIJKLMNOPQRSTUVWXYZabcdefghijklmnopqrstuvwxyz0123456789+/";

static void b64_quad(b64 *e, const uint8_t *t, int n)
{
    uint32_t v = (uint32_t)t[0] << 16 | (uint32_t)(n > 1 ? t[1] : 0) << 8 | (n > 2 ? t[2] : 0);
    if (e->no + 4 > sizeof e->out) {
        fwrite(e->out, 1, e->no, e->f);
        e->no = 0;
    }
    e->out[e->no++] = b64chars[v >> 18 & 63];
    e->out[e->no++] = b64chars[v >> 12 & 63];
    e->out[e->no++] = n > 1 ? b64chars[v >> 6 & 63] : '=';
    e->out[e->no++] = n > 2 ? b64chars[v & 63] : '=';
}

static void b64_put(b64 *e, const uint8_t *p, size_t n)
{
    while (n && e->nc) {
        e->carry[e->nc++] = *p++;
        n--;
        if (e->nc == 3) {
            b64_quad(e, e->carry, 3);
            e->nc = 0;
        }
    }
    while (n >= 3) {
        /* whole triplets straight into the output buffer */
        size_t room = (sizeof e->out - e->no) / 4, k = n / 3 < room ? n / 3 : room;
        char *o = e->out + e->no;
        if (!k) {
            fwrite(e->out, 1, e->no, e->f);
            e->no = 0;
            continue;
        }
        for (size_t q = 0; q < k; q++, p += 3, o += 4) {
            uint32_t v = (uint32_t)p[0] << 16 | (uint32_t)p[1] << 8 | p[2];
            o[0] = b64chars[v >> 18];
            o[1] = b64chars[v >> 12 & 63];
            o[2] = b64chars[v >> 6 & 63];
            o[3] = b64chars[v & 63];
        }
        e->no += 4 * k;
        n -= 3 * k;
    }
    while (n--) e->carry[e->nc++] = *p++;
}

static void b64_end(b64 *e)
{
    if (e->nc) b64_quad(e, e->carry, e->nc);
    e->nc = 0;
    fwrite(e->out, 1, e->no, e->f);
    e->no = 0;
}

/* ---- writing -------------------------------------------------------------- */

static void xml_array(FILE *f, const varr *a, ctl_vtk_enc enc, size_t offset, const char *indent)
{
    fprintf(f, "%s<DataArray type=\"%s\" Name=\"%s\" NumberOfComponents=\"%d\"", indent,
            type_name(a->type), a->name, a->ncomp);
    if (enc != CTL_VTK_ASCII) {
        fprintf(f, " format=\"appended\" offset=\"%zu\"/>\n", offset);
        return;
    }
    fputs(" format=\"ascii\">\n", f);
    for (size_t i = 0; i < a->ntuples; i++) {
        fputs(indent, f);
        for (int c = 0; c < a->ncomp; c++) {
            double v = value_at(a, i, c);
            if (a->type == VT_F64)
                fprintf(f, c ? " %.17g" : "%.17g", v);
            else
                fprintf(f, c ? " %lld" : "%lld", (long long)v + (a->kind == K_IOTA && a->w));
        }
        fputc('\n', f);
    }
    fprintf(f, "%s</DataArray>\n", indent);
}

/* Writes the array's appended bytes; raw and base64 lay the array out here,
 * one at a time, and release it after. */
static int appended_write(FILE *f, varr *a, ctl_vtk_enc enc)
{
    uint64_t n = a->nbytes;
    if (enc != CTL_VTK_ZLIB && layout(a)) return CTL_ESYS;
    if (enc == CTL_VTK_ZLIB) {
        fwrite(a->z, 1, a->zbytes, f);
    } else if (enc == CTL_VTK_BASE64) {
        b64 e = {.f = f};
        b64_put(&e, (const uint8_t *)&n, 8);
        b64_put(&e, a->bytes, a->nbytes);
        b64_end(&e);
    } else {
        fwrite(&n, 8, 1, f);
        if (a->nbytes) fwrite(a->bytes, 1, a->nbytes, f);
    }
    if (enc != CTL_VTK_ZLIB) release(a, 1);
    return 0;
}

/* Sizes every array for enc (zlib: compresses it now, raw and base64 lay
 * it out only when it is written); offsets[k] gets the
 * appended offset of array k. */
static int prepare(varr *a, size_t n, ctl_vtk_enc enc, size_t *offsets)
{
    size_t off = 0;
    if (enc == CTL_VTK_ASCII) return 0;
    for (size_t k = 0; k < n; k++) {
        if (enc == CTL_VTK_ZLIB) {
            /* the compressed size is known only once compressed */
            if (layout(&a[k]) || compress_array(&a[k])) return CTL_ESYS;
            if (a[k].own) free(a[k].bytes);
            a[k].bytes = NULL;
            a[k].own = 0;
        } else {
            a[k].nbytes = a[k].ntuples * (size_t)a[k].ncomp * type_size(a[k].type);
        }
        offsets[k] = off;
        off += appended_size(&a[k], enc);
    }
    return 0;
}

static FILE *open_out(const char *path)
{
    FILE *f = fopen(path, "wb");
    if (!f) fprintf(stderr, "mpmctl: cannot write %s: %s\n", path, strerror(errno));
    return f;
}

/* Closes f, reporting and removing path on any write error. */
static int close_out(FILE *f, const char *path, int rc)
{
    int werr = ferror(f);
    int e = errno;
    if (fclose(f) && !werr) {
        werr = 1;
        e = errno;
    }
    if (rc == CTL_ESYS && !werr)
        fprintf(stderr, "mpmctl: cannot write %s: out of memory or compression failed\n", path);
    if (werr) {
        fprintf(stderr, "mpmctl: cannot write %s: %s\n", path, strerror(e ? e : EIO));
        rc = CTL_ESYS;
    }
    if (rc) remove(path);
    return rc;
}

static void xml_head(FILE *f, const char *type, ctl_vtk_enc enc)
{
    fprintf(f,
            "<?xml version=\"1.0\"?>\n<VTKFile type=\"%s\" version=\"1.0\" byte_order=\"%s\" "
            "header_type=\"UInt64\"%s>\n",
            type, VTK_BYTE_ORDER,
            enc == CTL_VTK_ZLIB ? " compressor=\"vtkZLibDataCompressor\"" : "");
}

static int xml_tail(FILE *f, varr *a, size_t n, ctl_vtk_enc enc)
{
    if (enc != CTL_VTK_ASCII) {
        fprintf(f, "  <AppendedData encoding=\"%s\">\n   _",
                enc == CTL_VTK_BASE64 ? "base64" : "raw");
        for (size_t k = 0; k < n; k++)
            if (appended_write(f, &a[k], enc)) return CTL_ESYS;
        fputs("\n  </AppendedData>\n", f);
    }
    fputs("</VTKFile>\n", f);
    return 0;
}

enum { A_POINTS, A_CONN, A_OFFS, A_V, A_STRESS, A_P, A_MEAN, A_VOL, A_EP, A_F, A_Y, A_MAX };

int ctl_vtk_write_vtp(const char *path, const mpp_snapshot *s, ctl_vtk_enc enc)
{
    varr a[A_MAX];
    size_t off[A_MAX] = {0}, n = s->n, na = 0, idx[A_MAX];
    int dim = s->dim, rc;
    FILE *f;
    if (!s->x || dim < 1 || dim > 3) {
        fprintf(stderr,
                "mpmctl: %s: the snapshot at step %lld has no particle positions (dim %d): "
                "record X (output.snapshotFields empty or listing X) to write VTK\n",
                path, (long long)s->step, dim);
        return CTL_ECASE;
    }
    memset(a, 0, sizeof a);
    /* the order of the arrays in the appended section */
#define ADD(id, nm, ty, nc, kd, sr, ww)                                                         \
    do {                                                                                        \
        a[na] = (varr){                                                                         \
            .name = nm, .type = ty, .ncomp = nc, .ntuples = n, .kind = kd, .src = sr, .w = ww}; \
        idx[id] = na++;                                                                         \
    } while (0)
    for (int k = 0; k < A_MAX; k++) idx[k] = (size_t)-1;
    ADD(A_POINTS, "Points", VT_F64, 3, dim == 3 ? K_COPY : K_PAD, s->x, dim);
    ADD(A_CONN, "connectivity", VT_I64, 1, K_IOTA, NULL, 0);
    ADD(A_OFFS, "offsets", VT_I64, 1, K_IOTA, NULL, 1); /* w 1: i + 1 */
    if (s->v) ADD(A_V, "velocity", VT_F64, 3, dim == 3 ? K_COPY : K_PAD, s->v, dim);
    if (s->stress) ADD(A_STRESS, "stress", VT_F64, 9, K_VOIGT, s->stress, 6);
    if (s->pressure) ADD(A_P, "pressure", VT_F64, 1, K_COPY, s->pressure, 1);
    if (s->mean_stress) ADD(A_MEAN, "mean_stress", VT_F64, 1, K_COPY, s->mean_stress, 1);
    if (s->volume) ADD(A_VOL, "volume", VT_F64, 1, K_COPY, s->volume, 1);
    if (s->plastic_strain) ADD(A_EP, "plastic_strain", VT_F64, 1, K_COPY, s->plastic_strain, 1);
    if (s->deformation_gradient)
        ADD(A_F, "deformation_gradient", VT_F64, 9, dim == 3 ? K_COPY : K_F,
            s->deformation_gradient, dim);
    if (s->yielded) {
        ADD(A_Y, "yielded", VT_U8, 1, K_FLAG, NULL, 1);
        a[idx[A_Y]].isrc = s->yielded;
    }
#undef ADD
    rc = prepare(a, na, enc, off);
    if (rc) {
        release(a, na);
        fprintf(stderr, "mpmctl: cannot write %s: out of memory or compression failed\n", path);
        return rc;
    }
    if (!(f = open_out(path))) {
        release(a, na);
        return CTL_ESYS;
    }
    xml_head(f, "PolyData", enc);
    fputs("  <PolyData>\n    <FieldData>\n", f);
    fprintf(f,
            "      <DataArray type=\"Float64\" Name=\"TimeValue\" NumberOfTuples=\"1\" "
            "format=\"ascii\">%.17g</DataArray>\n",
            cj_norm(s->t));
    fprintf(f,
            "      <DataArray type=\"Int64\" Name=\"STEP\" NumberOfTuples=\"1\" "
            "format=\"ascii\">%lld</DataArray>\n",
            (long long)s->step);
    fprintf(f,
            "    </FieldData>\n    <Piece NumberOfPoints=\"%zu\" NumberOfVerts=\"%zu\" "
            "NumberOfLines=\"0\" NumberOfStrips=\"0\" NumberOfPolys=\"0\">\n",
            n, n);
    fputs("      <PointData", f);
    if (s->pressure) fputs(" Scalars=\"pressure\"", f);
    if (s->v) fputs(" Vectors=\"velocity\"", f);
    if (s->stress) fputs(" Tensors=\"stress\"", f);
    fputs(">\n", f);
    for (int id = A_V; id < A_MAX; id++)
        if (idx[id] != (size_t)-1) xml_array(f, &a[idx[id]], enc, off[idx[id]], "        ");
    fputs("      </PointData>\n      <Points>\n", f);
    xml_array(f, &a[idx[A_POINTS]], enc, off[idx[A_POINTS]], "        ");
    fputs("      </Points>\n      <Verts>\n", f);
    xml_array(f, &a[idx[A_CONN]], enc, off[idx[A_CONN]], "        ");
    xml_array(f, &a[idx[A_OFFS]], enc, off[idx[A_OFFS]], "        ");
    fputs("      </Verts>\n    </Piece>\n  </PolyData>\n", f);
    rc = xml_tail(f, a, na, enc);
    release(a, na);
    return close_out(f, path, rc);
}

int ctl_vtk_write_vti(const char *path, const ctl_vtk_grid *g, ctl_vtk_enc enc)
{
    double o[3] = {0, 0, 0}, h[3];
    uint64_t nn[3] = {1, 1, 1}, total;
    size_t off = 0;
    varr a;
    FILE *f;
    int rc;
    if (g->dim < 1 || g->dim > 3) {
        fprintf(stderr, "mpmctl: %s: the case's grid has dim %d (1..3 expected)\n", path, g->dim);
        return CTL_EPROTO;
    }
    for (int d = 0; d < 3; d++) {
        h[d] = g->spacing[0];
        if (d < g->dim) {
            o[d] = g->origin[d];
            h[d] = g->spacing[d];
            nn[d] = g->nodes[d] ? g->nodes[d] : 1;
        }
    }
    total = nn[0] * nn[1] * nn[2];
    memset(&a, 0, sizeof a);
    a = (varr){
        .name = "node", .type = VT_I64, .ncomp = 1, .ntuples = (size_t)total, .kind = K_IOTA};
    if ((rc = prepare(&a, 1, enc, &off))) {
        release(&a, 1);
        fprintf(stderr, "mpmctl: cannot write %s: out of memory\n", path);
        return rc;
    }
    if (!(f = open_out(path))) {
        release(&a, 1);
        return CTL_ESYS;
    }
    xml_head(f, "ImageData", enc);
    fprintf(f,
            "  <ImageData WholeExtent=\"0 %" PRIu64 " 0 %" PRIu64 " 0 %" PRIu64
            "\" Origin=\"%.17g %.17g %.17g\" Spacing=\"%.17g %.17g %.17g\">\n",
            nn[0] - 1, nn[1] - 1, nn[2] - 1, o[0], o[1], o[2], h[0], h[1], h[2]);
    fprintf(f, "    <Piece Extent=\"0 %" PRIu64 " 0 %" PRIu64 " 0 %" PRIu64 "\">\n", nn[0] - 1,
            nn[1] - 1, nn[2] - 1);
    fputs("      <PointData Scalars=\"node\">\n", f);
    xml_array(f, &a, enc, off, "        ");
    fputs("      </PointData>\n      <CellData>\n      </CellData>\n    </Piece>\n"
          "  </ImageData>\n",
          f);
    rc = xml_tail(f, &a, 1, enc);
    release(&a, 1);
    return close_out(f, path, rc);
}

int ctl_vtk_write_pvd(const char *path, const char *const *files, const double *times, size_t n)
{
    FILE *f = open_out(path);
    if (!f) return CTL_ESYS;
    fprintf(f,
            "<?xml version=\"1.0\"?>\n<VTKFile type=\"Collection\" version=\"0.1\" "
            "byte_order=\"%s\">\n  <Collection>\n",
            VTK_BYTE_ORDER);
    for (size_t i = 0; i < n; i++)
        fprintf(f, "    <DataSet timestep=\"%.17g\" group=\"\" part=\"0\" file=\"%s\"/>\n",
                cj_norm(times[i]), files[i]);
    fputs("  </Collection>\n</VTKFile>\n", f);
    return close_out(f, path, 0);
}
