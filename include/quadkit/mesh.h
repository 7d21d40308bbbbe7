/**
 * \file mesh.h
 * \brief Quadtree mesh generation (de Berg et al., Computational Geometry, ch. 14).
 *
 * Input: disjoint simple polygons ("components") with integer vertices in the domain
 * [0,U]^2, U a power of two, and edges at 0, 45, 90 or 135 degrees to the x-axis, as read
 * from Triangle's `.poly` format. Output: a conforming triangulation of the whole domain
 * that respects every component edge and whose angles all lie in [45, 90] degrees. The
 * generator follows the book: subdivide the domain square while a square larger than
 * unit size has a component boundary meeting its closure; balance the quadtree
 * (BalanceQuadTree); triangulate each leaf (along a component diagonal, along a square
 * diagonal, or with a Steiner point at the centre).
 *
 * Components are the cycles formed by the segments; component k (1-based) is the cycle
 * holding the k-th smallest of the cycles' smallest segment indices, so the cycle of
 * segment 0 is component 1. Every triangle carries the innermost component containing
 * it, or 0 outside all components. Triangles inside a hole region of the input (the
 * region, bounded by components, that holds a hole point) are dropped.
 *
 * All mesh vertices lie on the half-integer lattice, so their double coordinates are
 * exact.
 *
 * The dyadic-lattice mode (QK_MESH_DYADIC, chosen automatically for non-integer input, a
 * size bound, or integer input the book's mode cannot take: a vertex outside [0, 2^30])
 * runs the same algorithm on the coarsest lattice of spacing 2^-f, with its
 * origin at the input's lower-left corner, that holds every vertex exactly: real
 * coordinates at any position and scale, edges still at multiples of 45 degrees. Input
 * vertices come back bit-identical, every mesh vertex on a segment lies on it exactly,
 * and the [45, 90] degree bound holds (docs/mesh.md has the proofs). Inputs needing more
 * than 2^30 lattice steps across, or 2^24 along their segments, are refused rather than
 * rounded. Boundary markers and regional attributes are carried to the outputs.
 *
 * The general mode (QK_MESH_GENERAL, and QK_MESH_AUTO for inputs the two lattice modes
 * cannot take) meshes planar straight-line graphs with any double coordinates and any
 * angles (holes, several components, internal segments, open chains) by quality Delaunay
 * refinement seeded from a graded quadtree: every angle at least 20 degrees (or
 * min_angle_deg) and at most 140 (180 - 2 x the bound) except inside input angles below
 * 60 degrees; input vertices bit-identical, every vertex on a segment exactly on it
 * (docs/mesh.md, "The general mode", has the algorithm and the proof). It takes touching
 * input: a vertex exactly inside a segment splits the segment there, and a segment that
 * repeats another, wholly or along a stretch, is merged into the earlier one (its mesh
 * edges are reported as that segment's, with its marker; the merged segment's own marker
 * goes to no edge and no vertex); stats count both. More than 2^16 + 16 (vertices +
 * segments) such splits are refused (QK_ERR_LIMIT): many segments overlapping along a
 * line through many vertices would cost a walk each.
 * QK_MESH_AUTO runs it also where a lattice mode it chose refuses segments that meet
 * (touching components), keeping the lattice mode's message when both refuse a crossing
 * (two segments meeting away from any vertex) or it refuses the options (min_angle_deg
 * above 34), its own otherwise (a crossing behind a touch the lattice mode named).
 *
 * Thread safety: a mesh and a qk_poly never change once made, so any number of threads
 * may call the functions taking a const handle (accessors, statistics, writers) on one
 * mesh at once, and qk_mesh_generate() only reads its input, so several threads may mesh
 * one qk_poly concurrently (each with its own allocator, or libc's).
 */
#ifndef QUADKIT_MESH_H
#define QUADKIT_MESH_H

#include <stdio.h>

#include "quadkit/index.h"

#ifdef __cplusplus
extern "C" {
#endif

/** Largest accepted domain size (2^30), which keeps all arithmetic exact in 64 bits. */
#define QK_MESH_MAX_SIZE (1ull << 30)

/** Where and why a mesh input was rejected (the library-wide error record). */
typedef qk_error_t qk_mesh_error_t;

/** Opaque planar straight-line input: vertices, segments, hole points. */
typedef struct qk_poly qk_poly_t;

/**
 * Read Triangle's `.poly` format: vertices (`#` comments, first index 0 or 1, optional
 * attributes, which are ignored, and boundary markers, which qk_mesh_vertex_markers() and
 * the outputs carry), segments, a holes section
 * (required, "0" for none, as in Triangle) and optional regional attributes. Only syntax
 * is checked here; the geometry is checked by qk_mesh_generate(). Numbers are read in the
 * C locale, as every writer below writes them, whatever locale the program or the calling
 * thread set (setlocale, uselocale): "1.5", never "1,5". Reading stops at the
 * first NUL byte (binary data), at a carriage return not followed by a line feed and at a
 * line longer than 1 MiB (1048576 bytes), so an endless stream is never taken into memory.
 * \param [in] f an open stream, owned by the caller.
 * \param [in] allocator NULL for libc; copied.
 * \param [out] out the input, freed with qk_poly_free(); NULL on error.
 * \param [out] err where and why the input was rejected (may be NULL).
 * \return QK_OK, QK_ERR_PARSE, QK_ERR_LIMIT (absurd counts, a line past 1 MiB), QK_ERR_IO
 *         or QK_ERR_NOMEM (also when the C locale cannot be made: every reader and writer
 *         of the library returns it then).
 */
qk_status_t qk_poly_read(FILE *f, const qk_allocator_t *allocator, qk_poly_t **out,
                         qk_mesh_error_t *err);

/**
 * Make an input from arrays (0-based indices).
 * \param [in] xy 2*nv vertex coordinates, copied; finite (the book's mode needs integers).
 * \param [in] nv number of vertices.
 * \param [in] seg 2*ns vertex indices, copied.
 * \param [in] ns number of segments.
 * \param [in] holes 2*nh hole point coordinates, copied (may be NULL when nh is 0).
 * \param [in] nh number of hole points.
 * \param [in] allocator NULL for libc; copied.
 * \param [out] out the input, freed with qk_poly_free().
 * \param [out] err which array item was rejected and why (may be NULL); line is 0.
 * \return QK_OK, QK_ERR_INVALID (a missing array, a coordinate not finite, an endpoint
 *         that is not a vertex number), QK_ERR_LIMIT (over 2^26 items) or QK_ERR_NOMEM.
 */
qk_status_t qk_poly_from_arrays(const double *xy, size_t nv, const uint32_t *seg, size_t ns,
                                const double *holes, size_t nh, const qk_allocator_t *allocator,
                                qk_poly_t **out, qk_mesh_error_t *err);

/** Free an input; NULL is a no-op. */
void qk_poly_free(qk_poly_t *poly);

/** First vertex index used by the input file (0 or 1; 0 for arrays). */
unsigned qk_poly_first_index(const qk_poly_t *poly);

/**
 * Round every vertex coordinate to the nearest multiple of step (ties to even), in place:
 * vertex numbers, line numbers, boundary markers, hole points and regional attributes
 * stay as read, so errors still name the file's lines and numbers. qk_mesh_generate()
 * then refuses (QK_ERR_GEOMETRY, naming it) a hole or regional attribute point nearer a
 * segment than the rounding moved either end of it, which may have moved it across.
 * \param [in,out] poly the input.
 * \param [in] step the grid step, positive and finite.
 * \param [out] rounded how many coordinates changed (may be NULL).
 * \return QK_OK, QK_ERR_INVALID (no input, or step not positive and finite),
 *         QK_ERR_NONFINITE (a rounded coordinate would overflow; nothing is changed) or
 *         QK_ERR_NOMEM (nothing is changed).
 */
qk_status_t qk_poly_round(qk_poly_t *poly, double step, size_t *rounded);

/** Number of vertices, segments and hole points of an input (any pointer may be NULL). */
void qk_poly_counts(const qk_poly_t *poly, size_t *nv, size_t *ns, size_t *nh);

/**
 * Copy an input's vertices (x, y pairs, 0-based order) into a caller's buffer.
 * \param [in] poly the input.
 * \param [out] xy room for 2*cap doubles (may be NULL when cap is 0).
 * \param [in] cap vertices the buffer holds; at most this many are written.
 * \param [out] n_out the number of vertices of the input (all of them, even beyond cap).
 * \return QK_OK, or QK_ERR_INVALID for a NULL input or n_out.
 */
qk_status_t qk_poly_vertices(const qk_poly_t *poly, double *xy, size_t cap, size_t *n_out);

/**
 * Copy an input's segments (pairs of 0-based vertex indices) into a caller's buffer.
 * \param [in] poly the input.
 * \param [out] seg room for 2*cap indices (may be NULL when cap is 0).
 * \param [in] cap segments the buffer holds; at most this many are written.
 * \param [out] n_out the number of segments of the input.
 * \return QK_OK, or QK_ERR_INVALID for a NULL input or n_out.
 */
qk_status_t qk_poly_segments(const qk_poly_t *poly, uint32_t *seg, size_t cap, size_t *n_out);

/**
 * Copy an input's hole points (x, y pairs) into a caller's buffer.
 * \param [in] poly the input.
 * \param [out] xy room for 2*cap doubles (may be NULL when cap is 0).
 * \param [in] cap hole points the buffer holds; at most this many are written.
 * \param [out] n_out the number of hole points of the input.
 * \return QK_OK, or QK_ERR_INVALID for a NULL input or n_out.
 */
qk_status_t qk_poly_holes(const qk_poly_t *poly, double *xy, size_t cap, size_t *n_out);

/**
 * Attach boundary markers to an input made from arrays (a `.poly` file carries its own).
 * Call before the input is shared: it is the one call that changes a qk_poly.
 * \param [in,out] poly the input.
 * \param [in] vertex_markers one per vertex, copied (NULL: none).
 * \param [in] segment_markers one per segment, copied (NULL: none).
 * \param [out] err why the call failed (may be NULL).
 * \return QK_OK, QK_ERR_INVALID or QK_ERR_NOMEM (the input unchanged).
 */
qk_status_t qk_poly_set_markers(qk_poly_t *poly, const int32_t *vertex_markers,
                                const int32_t *segment_markers, qk_mesh_error_t *err);

/**
 * Attach regional attributes to an input made from arrays: each (x, y, attribute) triple
 * gives its attribute to the region (the connected part of the domain between segments)
 * holding the point. Replaces any attached before; same rule as qk_poly_set_markers().
 * \param [in,out] poly the input.
 * \param [in] xya 3*nr doubles, copied.
 * \param [in] nr number of regional attributes.
 * \param [out] err which triple was rejected and why (may be NULL).
 * \return QK_OK, QK_ERR_INVALID (a value not finite) or QK_ERR_NOMEM (input unchanged).
 */
qk_status_t qk_poly_set_regions(qk_poly_t *poly, const double *xya, size_t nr,
                                qk_mesh_error_t *err);

/** Which mesher qk_mesh_generate() runs. */
typedef enum qk_mesh_mode {
  /** The book's mode when the input has integer coordinates in [0, 2^30] and no size bound
   *  is asked for (or a domain size is given), the dyadic-lattice mode for other inputs on
   *  a dyadic lattice it accepts (integer input elsewhere included), when the input meets that
   * mode's conditions (segments at 0, 45, 90 or 135 degrees, every vertex on exactly two segments);
   * the general mode otherwise. */
  QK_MESH_AUTO = 0,
  /** The book's mode (de Berg et al. ch. 14): integer vertices in [0,U]^2. */
  QK_MESH_BOOK = 1,
  /** The same algorithm on the coarsest dyadic lattice (spacing 2^-f, origin at the
   *  input's lower-left corner) holding every vertex exactly: real coordinates that are
   *  dyadic rationals, any position, edges still at 0, 45, 90 or 135 degrees. */
  QK_MESH_DYADIC = 2,
  /** The general mode: planar straight-line graphs with any double coordinates and any
   *  angles (holes, open chains, internal segments), meshed by quality Delaunay
   *  refinement seeded from a graded quadtree (docs/mesh.md, "The general mode"): every
   *  angle at least min_angle_deg except inside input angles below 60 degrees. */
  QK_MESH_GENERAL = 3
} qk_mesh_mode_t;

/** A size function: the longest edge wanted near (x, y) (input coordinates). */
typedef double (*qk_mesh_size_fn)(double x, double y, void *user);

/** Options for qk_mesh_generate(); zero-initialise or use qk_mesh_options_init(). */
typedef struct qk_mesh_options {
  /** Domain side U, a power of two; 0 means the smallest power of two >= every
   *  coordinate (and >= 1). The book's mode only. */
  uint64_t size;
  /** Allocator for the mesh and its tree; NULL means libc (on Linux the mesher then
   *  takes blocks of 64 KB and more from 2 MB chunks of their own, mapped
   *  with transparent huge pages and kept until qk_mesh_free(), after which up to 64 MB
   *  of them stay mapped for the next mesh until qk_mesh_trim(); docs/mesh.md, "Speed"). */
  const qk_allocator_t *allocator;
  /** Which mesher; QK_MESH_AUTO by default. */
  qk_mesh_mode_t mode;
  /** Longest triangle edge wanted, in input units (0: no bound). Guaranteed: every edge
   *  is at most this long (in the book's mode it must be at least sqrt 2). */
  double max_size;
  /** Size function (NULL: none), sampled at each leaf's corners and centre: a leaf is
   *  split while its triangles' longest possible edge exceeds the smallest sample. The
   *  general mode also samples it at every triangle's centroid and splits a triangle whose
   *  longest edge exceeds it. A sample that is not a positive number (0, negative, NaN)
   *  bounds nothing there; +inf neither. With max_size as well, the smaller bound holds.
   *  The book's and the dyadic mode split no leaf below the lattice's unit square: a
   *  sample asking for less is refused (QK_ERR_LIMIT), and QK_MESH_AUTO meshes such input
   *  in the general mode. */
  qk_mesh_size_fn size_fn;
  /** Passed to size_fn. */
  void *size_user;
  /** The general mode's minimum angle in degrees (0: the default, 20, which is proven;
   *  larger values up to 34 are tried with no termination proof and refused with
   *  QK_ERR_LIMIT when the refinement does not settle). Other modes: must be 0 or at most
   *  45 (their proven bound). */
  double min_angle_deg;
} qk_mesh_options_t;

/** Fill options with the defaults. \param [out] options the options. */
void qk_mesh_options_init(qk_mesh_options_t *options);

/** Opaque mesh handle. */
typedef struct qk_mesh qk_mesh_t;

/**
 * Validate the input and generate its mesh.
 * \param [in] poly the input (borrowed; only read during the call).
 * \param [in] options NULL for defaults.
 * \param [out] out the mesh, freed with qk_mesh_free(); NULL on error.
 * \param [out] err where and why the input was rejected (may be NULL).
 * \return QK_OK, QK_ERR_INVALID (bad option), QK_ERR_GEOMETRY (the lattice modes:
 *         non-integer or out-of-domain coordinates, bad angles, open chains, degree != 2,
 *         intersecting or touching components, hole point on a boundary or outside; the
 *         general mode: duplicate vertices, crossing segments, a vertex on a segment that
 *         rounding (qk_poly_round) may have put there, a hole or region point on a segment
 *         or a vertex, or a segment that must be split
 *         where its endpoints allow no exact point), QK_ERR_LIMIT (too large; the general
 *         mode: a refinement that does not settle, or precision exhausted) or QK_ERR_NOMEM.
 */
qk_status_t qk_mesh_generate(const qk_poly_t *poly, const qk_mesh_options_t *options,
                             qk_mesh_t **out, qk_mesh_error_t *err);

/** Free a mesh; NULL is a no-op. */
void qk_mesh_free(qk_mesh_t *mesh);

/**
 * Give back to the system the memory the mesher keeps mapped for later meshes (up to
 * 64 MB of the chunks of freed meshes made without an allocator; see
 * qk_mesh_options_t.allocator). Safe from any thread; a call made while another thread
 * is taking or returning chunks returns without trimming.
 */
void qk_mesh_trim(void);

/**
 * The mesh vertices as 2*n doubles (x, y), borrowed until qk_mesh_free().
 * \param [in] mesh the mesh. \param [out] n the number of vertices.
 * \return the coordinates.
 */
const double *qk_mesh_vertices(const qk_mesh_t *mesh, size_t *n);

/**
 * The triangles as 3*n 0-based vertex indices, counter-clockwise, borrowed.
 * \param [in] mesh the mesh. \param [out] n the number of triangles.
 * \return the indices.
 */
const uint32_t *qk_mesh_triangles(const qk_mesh_t *mesh, size_t *n);

/**
 * Per vertex, its boundary marker: the vertex's own marker from the input when it is an
 * input vertex with a nonzero one, else the marker of an input segment through it (the
 * first in input order with a nonzero marker), else 0. Borrowed.
 * \param [in] mesh the mesh. \param [out] n the number of entries (the vertices).
 * \return the markers.
 */
const int32_t *qk_mesh_vertex_markers(const qk_mesh_t *mesh, size_t *n);

/**
 * Per triangle, the regional attribute of its region (0 where no regional attribute
 * point lies), or NULL when the input has no regional attributes. Borrowed.
 * \param [in] mesh the mesh. \param [out] n the number of entries (the triangles).
 * \return the attributes.
 */
const double *qk_mesh_triangle_attributes(const qk_mesh_t *mesh, size_t *n);

/**
 * The mesh edges that make up the input segments, into a caller's buffer: per edge its
 * two vertex indices, the input segment it lies on and that segment's marker. Segments
 * with holes on both sides have no mesh edges.
 * \param [in] mesh the mesh.
 * \param [out] ab room for 2*cap vertex indices (may be NULL when cap is 0).
 * \param [out] seg room for cap segment indices (may be NULL).
 * \param [out] marker room for cap markers (may be NULL).
 * \param [in] cap edges the buffers hold.
 * \param [out] n_out the number of such edges (all of them, even beyond cap).
 * \return QK_OK, or QK_ERR_INVALID for a NULL mesh or n_out.
 */
qk_status_t qk_mesh_segments(const qk_mesh_t *mesh, uint32_t *ab, uint32_t *seg, int32_t *marker,
                             size_t cap, size_t *n_out);

/**
 * Histogram of the triangles' angles in 1-degree bins: bins[k] counts the angles in
 * [k, k + 1) degrees (180 bins, 3 angles per triangle; computed in floating point, so an
 * angle of exactly 45 may land in bin 44).
 * \param [in] mesh the mesh. \param [out] bins 180 counters, overwritten.
 * \return QK_OK, or QK_ERR_INVALID for NULL arguments.
 */
qk_status_t qk_mesh_angle_histogram(const qk_mesh_t *mesh, uint64_t bins[180]);

/**
 * Per triangle, the innermost component containing it (0: outside all), borrowed. The
 * general mode: the face holding it (1-based over the kept faces, the connected parts of
 * the domain between segments).
 * \param [in] mesh the mesh. \param [out] n the number of entries (the triangles).
 * \return the component ids.
 */
const uint32_t *qk_mesh_triangle_components(const qk_mesh_t *mesh, size_t *n);

/** The balanced quadtree subdivision the mesh was made from (borrowed). In the general
 *  mode, the tree graded by the input's features (a leaf is split while it is near two
 *  features that need separating), over [0, 1]^2 in lattice coordinates, and not balanced;
 *  that mode's points are the refinement's, and the tree only checks the input and sizes
 *  the work, so it is graded only when needed: with a size function, or when the
 *  refinement outgrew the work the input's size allows (docs/mesh.md, "The general mode").
 *  Otherwise NULL, as on most inputs. */
const qk_tree_t *qk_mesh_tree(const qk_mesh_t *mesh);

/** Figures about a mesh and its generation. */
typedef struct qk_mesh_stats {
  uint64_t size;                   /**< the domain side U (general mode: 1, in lattice units) */
  size_t components;               /**< number of components */
  size_t leaves_before_balance;    /**< leaves of the subdivision (general mode: of the
                                        graded tree; 0 when it was not graded) */
  size_t leaves;                   /**< leaves after balancing (general mode: not balanced) */
  size_t triangles;                /**< triangles kept */
  size_t vertices;                 /**< vertices used by them */
  size_t steiner;                  /**< Steiner points used (square centres; general mode:
                                        every vertex not in the input) */
  double min_angle_deg;            /**< smallest triangle angle */
  double max_angle_deg;            /**< largest triangle angle */
  double uniform_triangles;        /**< 2 U^2, the size of the uniform grid mesh */
  qk_mesh_mode_t mode;             /**< the mesher that ran: QK_MESH_BOOK, _DYADIC or _GENERAL */
  int lattice_exponent;            /**< f: lattice spacing 2^-f input units (0: the book's;
                                        general mode: -e for the root square's side 2^e) */
  double origin_x, origin_y;       /**< input coordinates of lattice point (0, 0) */
  double proven_min_angle_deg;     /**< the proven lower bound on every angle (45; general
                                        mode: the bound, 20 by default, outside exempt
                                        triangles, or 0 when min_angle_deg > 20.7 was asked) */
  double proven_max_angle_deg;     /**< the proven upper bound on every angle (90; general
                                        mode: 180 - 2 x the bound, or 180) */
  size_t exempt_angles;            /**< general mode: angles below the bound, all in triangles
                                        facing input angles below 60 degrees */
  double smallest_input_angle_deg; /**< general mode: the smallest angle between two input
                                        segments at a vertex (180 when none) */
  size_t split_vertices;           /**< general mode: times an input vertex lay inside an
                                        input segment (or a piece of one), splitting it there
                                        (a vertex inside k segments counts k times) */
  size_t merged_segments;          /**< general mode: input segments (or pieces of them)
                                        that repeated an earlier one, merged into it */
  double seconds_validate;         /**< checking the input */
  double seconds_subdivide;        /**< step 1 */
  double seconds_balance;          /**< step 2 */
  double seconds_triangulate;      /**< step 3, components and holes included */
} qk_mesh_stats_t;

/**
 * Fill stats for a mesh. In the general mode the smallest and largest angle and
 * exempt_angles are computed here, one pass over the triangles a call (the generation
 * does not spend it on a caller that never asks); the other figures are stored.
 * \param [in] mesh the mesh. \param [out] stats the figures.
 */
void qk_mesh_stats(const qk_mesh_t *mesh, qk_mesh_stats_t *stats);

/**
 * Write the vertices in Triangle's `.node` format, with a boundary marker column when the
 * input carried markers.
 * \param [in] mesh the mesh. \param [in] f an open stream (caller's).
 * \param [in] first_index 0 or 1, the first vertex number.
 * \return QK_OK or QK_ERR_IO (the stream is flushed, so a write it refused is seen).
 */
qk_status_t qk_mesh_write_node(const qk_mesh_t *mesh, FILE *f, unsigned first_index);

/**
 * Write the triangles in Triangle's `.ele` format, counter-clockwise, with the
 * component id as the first triangle attribute and, when the input has regional
 * attributes, the triangle's regional attribute as the second.
 * \param [in] mesh the mesh. \param [in] f an open stream (caller's).
 * \param [in] first_index 0 or 1, as for the `.node` file.
 * \return QK_OK or QK_ERR_IO (the stream is flushed, so a write it refused is seen).
 */
qk_status_t qk_mesh_write_ele(const qk_mesh_t *mesh, FILE *f, unsigned first_index);

/**
 * Write the mesh edges along input segments in Triangle's `.poly` format (no vertices:
 * they are the `.node` file's; segments with their markers; no holes).
 * \param [in] mesh the mesh. \param [in] f an open stream (caller's).
 * \param [in] first_index 0 or 1, as for the `.node` file.
 * \return QK_OK, QK_ERR_INVALID or QK_ERR_IO (the stream is flushed, so a write it
 *         refused is seen).
 */
qk_status_t qk_mesh_write_poly(const qk_mesh_t *mesh, FILE *f, unsigned first_index);

/**
 * Write gmsh's `.msh` 4.1 ASCII format: one physical group per component id present
 * (named "component_K", and "outside" for 0) and, when the input has regional attributes,
 * one per attribute value present ("region_A"); one surface entity per component (with
 * attributes: per component and attribute) carrying its groups; when the input carries
 * boundary markers, one curve entity and one physical group of line elements (the mesh
 * edges along input segments) per marker present (named "marker_M").
 * \param [in] mesh the mesh. \param [in] f an open stream (caller's).
 * \return QK_OK or QK_ERR_IO (the stream is flushed, so a write it refused is seen).
 */
qk_status_t qk_mesh_write_msh(const qk_mesh_t *mesh, FILE *f);

/**
 * Write VTK's XML unstructured grid (`.vtu`, ASCII) with the component id ("component"
 * and "region"), the regional attribute when there are regions, as cell data and the
 * boundary marker ("marker") as point data.
 * \param [in] mesh the mesh. \param [in] f an open stream (caller's).
 * \return QK_OK or QK_ERR_IO (the stream is flushed, so a write it refused is seen).
 */
qk_status_t qk_mesh_write_vtu(const qk_mesh_t *mesh, FILE *f);

/**
 * Draw the mesh as SVG: triangles shaded by component, the quadtree leaves, and the
 * component boundaries on top.
 * \param [in] mesh the mesh. \param [in] f an open stream (caller's).
 * \param [in] width picture width in pixels (0 means 800).
 * \return QK_OK or QK_ERR_IO (the stream is flushed, so a write it refused is seen).
 */
qk_status_t qk_mesh_write_svg(const qk_mesh_t *mesh, FILE *f, unsigned width);

#ifdef __cplusplus
}
#endif

#endif /* QUADKIT_MESH_H */
