"""Every test tolerance in one table, each with the reason for its size.

Sections belong to modules; add entries to your module's section only.
"""

# --- shared -----------------------------------------------------------------------------
#: float64 closed forms of a few operations on values of order 1 (rotations, unit vectors,
#: pixel maps, metres near 1 m): rounding leaves ~1e-15; 1e-12 allows a few hundred
#: roundings and still fails on any formula, sign or convention error.
FLOAT64_EXACT = 1e-12

# --- objects ----------------------------------------------------------------------------
#: size of a mesh written to STL/PLY and read back: the files hold float32 vertices, ~6e-8
#: relative rounding (measured 2.2e-8 for both formats).
MESH_FILE_REL = 1e-6

# --- optics -----------------------------------------------------------------------------
#: project(unproject(p)) vs p over the whole image with realistic distortion. The iterative
#: undistortion converges to machine precision; 1e-6 px is the issue's requirement.
ROUND_TRIP_PX = 1e-6
#: our project() vs cv2.projectPoints: same formula in float64, only summation order differs.
OPENCV_AGREEMENT_PX = 1e-9
#: inverse camera model at Z = 1 m vs the nominal 0.500 m x 0.625 m (issue requirement).
PROJECTED_SIZE_M = 1e-4
#: our Newton undistortion vs cv2.undistortPoints run to convergence (200 iterations, eps
#: 1e-15): both reach the same inverse, measured 2e-13 px; 1e-6 px is the round-trip budget.
OPENCV_UNDISTORT_PX = 1e-6
#: default camera focal length vs the paper's 2285.77 px, which is quoted to two decimals
#: (half a unit in the last place; measured 0.0013 px).
PAPER_FOCAL_PX = 0.005
#: Isaac camera parameters -> intrinsics -> back: a few float64 divisions on values of order
#: 1000 px (measured exactly 0).
ISAAC_ROUND_TRIP_PX = 1e-9

# --- patterns / phase -------------------------------------------------------------------
#: decoding noise-free float frames: the least-squares phase is exact up to float rounding
#: (measured ~1e-13 rad); 1e-9 rad still fails on any sign or shift error.
PHASE_EXACT_RAD = 1e-9
#: projector coordinates decoded from the same noise-free frames or exact wrapped phases:
#: u_p = T phi / (2 pi) turns ~1e-13 rad into ~1e-12 px; 1e-9 px fails on any sign, shift
#: or fringe-order error (a whole period, >= 10 px).
DECODE_EXACT_PX = 1e-9
#: background A and modulation B from the same frames: float64 least squares on values of at
#: most a few hundred digital numbers, rounding ~1e-13 DN.
INTENSITY_EXACT_DN = 1e-9
#: decode RMS after 8-bit camera quantisation (issue requirement). Quantisation (0.29 DN
#: RMS) gives 0.004 px (18 steps) to 0.007 px (6-step heterodyne) measured at B ~ 70 DN.
DECODE_RMS_PX = 0.02
#: largest single decode error in the same tests: measured <= 0.035 px over 1e6 points; a
#: fringe-order error moves a point by a whole period (>= 16 px), so 0.1 px catches it.
DECODE_MAX_PX = 0.1
#: measured phase std vs sigma_phi = (sigma / B) sqrt(2 / N) (issue requirement: 20 %). With
#: 40 000 pixels the std's own sampling error is 0.4 %, so a wrong N or B dependence fails.
NOISE_STD_REL = 0.2
#: Gray-code transitions vs the half-period boundaries k T / 2: transitions fall between pixel
#: centres, so each sits exactly half a pixel from a boundary that is a pixel centre
#: (measured 0.5 px everywhere); a transition one pixel off would be 1.5 px away.
GRAY_EDGE_PX = 0.5
#: wrapped phase of the finest period from 8-bit quantised frames (B / 2 = 60-95 DN):
#: measured max 0.006 rad (default) and 0.0089 rad (heterodyne) over 20 000 points.
DECODE_PHASE_8BIT_RAD = 0.01
#: background A and modulation B from the same 8-bit frames: rounding to whole DN leaves
#: measured max 0.28 DN (A) and 0.63 DN (B).
INTENSITY_8BIT_DN = 1.0
#: largest residual of heterodyne unwrapping from exact wrapped phases: float64 rounding
#: (measured 7e-13 rad); a wrong beat or period ratio gives residuals of order 1 rad.
HETERODYNE_RESIDUAL_EXACT = 1e-6
#: codes without the complementary frame: both ends of a one-period code cell have the
#: same phase, so a point closer to a code edge than the phase error is ambiguous. The 8-bit
#: round trips (phase error <= 0.035 px) leave out random points within 0.05 px of a code
#: edge; points at half periods are always kept (a code edge is never there).
CODE_EDGE_BAND_PX = 0.05
#: square-wave fringes: largest decoded phase error vs the harmonic series of the projected
#: profile (issue requirement 10 %); the same frames, so they agree to float rounding.
BINARY_FRINGE_PREDICTION_REL = 0.1
#: share of valid pixels flagged under a wrong description (issue requirement: > 20 %);
#: measured ~50 % (alignment swapped) and ~90 % (bit order swapped).
FLAGGED_WRONG_MIN = 0.2
#: ... and under the right one (issue requirement < 0.5 %; measured 0).
FLAGGED_CORRECT_MAX = 0.005
#: flagged share with noise sigma = 2 DN at B = 30 DN over 180 DN of ambient light: the
#: 6-step heterodyne residual's tail above 0.4 pi (measured 0.94 %; temporal 0.02 %, code
#: sequences 0).
FLAGGED_NOISY_MAX = 0.02
#: valid share under that noise: 6-step heterodyne pixels whose residual passes pi/2 are
#: invalid (measured 99.95 %; 95.4 % at B = 20 DN); the other sequences keep 100 %.
NOISY_VALID_MIN = 0.99
#: sharp 18-step binary fringes on a DMD decode to a staircase (each projector pixel one
#: value, +-0.5 px) plus the square wave's aliased harmonics (measured <= 0.17 rad at
#: P = 36, about 1 px; max error measured 0.5 px at P = 18 and 1.0 px at P = 36): an order
#: error is 18 px or more.
DECODE_BINARY_MAX_PX = 1.5
#: the same fringes through a defocused projector (blur sigma 1 camera px): measured max
#: 0.19 px; 0.5 px is still far from an order error.
DECODE_BLURRED_BINARY_MAX_PX = 0.5

# --- reconstruct ------------------------------------------------------------------------
#: triangulating exact correspondences (issue requirement). Closed-form ray intersection in
#: float64 reaches ~1e-13 m; Newton refinement for distorted projectors stops at 1e-9 px.
TRIANGULATION_M = 1e-6
#: median 3D error of the decoded free-form scan against the renderer's ground-truth points
#: (true rig, blurred projector pixels, 4 spp): the decoded u_p/v_p carry ~0.02-0.05 px of
#: sampling noise, ~10 um in depth at 1 m; 50 um would mean a systematic decoding or
#: triangulation error.
PIPELINE_TRUE_RIG_M = 5e-5
#: the same capture reconstructed from the rig stored as OpenCV YAML or the paper's text files
#: instead of JSON: both round-trip the parameters to ~1e-16 (measured), so the points agree
#: to float rounding; 1 nm would catch a lost digit or a mm/m slip.
PIPELINE_FORMAT_M = 1e-9
#: unit normals of an exact point map of a fronto-parallel plane vs (0, 0, -1): float64
#: cross products of neighbour differences (measured 7e-13).
NORMALS_EXACT = 1e-6

# --- pipeline (turntable, demo) ---------------------------------------------------------
#: ICP correction after merging turntable views with the true rig and known poses (the views
#: are already in place): measured 0.0012 deg and 2.8 um (4 views), 0.0008-0.0012 deg and
#: 7e-5-1e-4 mm per view with --refine; what remains is the decoded clouds' noise.
TURNTABLE_ICP_ANGLE_DEG = 0.01
TURNTABLE_ICP_SHIFT_M = 1e-4
TURNTABLE_REFINE_SHIFT_MM = 0.01

# --- render -----------------------------------------------------------------------------
#: renderer vs Mitsuba's own projector emitter, same (unjittered) sample positions: mean
#: |difference| / mean radiance. The issue asks for 1 %; measured ~1e-5 (float32 rounding and
#: a few samples lying exactly on DMD pixel edges), so 1e-3 still catches any model error.
MITSUBA_AGREEMENT_REL = 1e-3
#: its signed counterpart, |mean difference| / mean radiance, against Mitsuba's jittered
#: sampler (4 spp, 160 x 160 px): sampling noise (std 0.6e-3 per frame over 10 seeds) plus
#: aliasing of our fixed 2 x 2 grid against binary stripes (-1.6e-3 mean on one Gray
#: complement frame); measured |bias| <= 2.7e-3 over 10 seeds.
MITSUBA_JITTERED_BIAS_REL = 5e-3
#: white-frame radiance of a Lambertian plane facing the projector vs rho / D^2 (closed
#: form of the point-source model). float32 shading: measured ~1e-7 relative.
RADIANCE_REL = 1e-5
#: decoded vs ground-truth projector coordinates, tilted plane, bilinear lookup, 4 spp,
#: 8 bit, noise-free: issue requirement 0.02 px; measured 0.003 px.
DECODE_BILINEAR_RMS_PX = 0.02
#: DMD (nearest) staircase on a tilted plane, RMS px. A 1-px step sampled by 4 stratified
#: points leaves ~0.15 px (0.29 = 1/sqrt(12) without any averaging); the bounds show it is
#: the staircase, neither smoothed away (< 0.08) nor larger than unfiltered steps.
NEAREST_STAIRCASE_RMS_PX = (0.08, 0.29)
#: share of pixels where both the decode and the ground truth are valid on the tilted plane
#: (8 bit, 4 spp): measured 1.0 for both lookups; edge pixels may fail the modulation test.
DECODE_VALID_FRACTION_MIN = 0.99
#: ground-truth depth vs the analytic plane: Mitsuba intersects in float32 (~1e-7 relative
#: at 1 m; measured 3e-7 m); issue requirement 1e-6 m.
PLANE_DEPTH_M = 1e-6
#: ground-truth proj_uv vs projecting ground-truth points (issue: 1e-4 px); both float64,
#: measured 1e-13 px.
GT_PROJ_UV_PX = 1e-4
#: default sphere radius from decoded frames and the true rig (issue: 0.02 mm); measured
#: 0.011 mm (nearest, the default) and 0.001 mm (bilinear).
SPHERE_RADIUS_M = 2e-5
#: sphere centre from the same fit: measured 14 um (nearest) and 1.3 um (bilinear).
SPHERE_CENTRE_DECODED_M = 10 * SPHERE_RADIUS_M
#: identical geometry traced two ways (box primitive vs the same box as a mesh, camera moved
#: vs scene moved): Mitsuba intersects in float32, ~1e-7 m typically; a sphere's quadratic
#: loses digits at grazing incidence (measured up to 3e-6 m at the limb).
SAME_GEOMETRY_M = 1e-5
#: frames of that identical geometry (camera vs scene moved): float32 hits flip the 8-bit
#: rounding by 1 DN at a few pixels (measured 6e-4 of all values) ...
SAME_GEOMETRY_FLIP_FRACTION = 1e-3
#: ... and only where a supersample's shadow ray grazes an occluder more (measured 2 pixels).
SAME_GEOMETRY_GRAZING_PIXELS = 5
#: mean of the stratified sample offsets of a pixel: symmetric float64 grid, measured <= 1e-17.
SAMPLE_OFFSET_MEAN_PX = 1e-15
#: ground-truth normals are float32 (Mitsuba): unit length and plane normal to measured
#: 1.6e-7 and 8.7e-8.
GT_NORMAL = 1e-6
#: white frame from synthesis vs the traced white radiance: the same float32 values
#: (measured identical).
SYNTHESIS_WHITE_REL = 1e-6
#: one quantisation step: float32 radiance times exposure rounds the other way when it lies at
#: a .5 midpoint (16-bit frames vs np.rint, and the Dr.Jit vs sparse synthesis paths).
FRAME_ROUNDING_DN = 1
#: share of values where the Dr.Jit and sparse paths differ by that step (float32 sums in
#: another order): measured 5e-4.
JIT_FLIP_FRACTION = 1e-3
#: auto exposure puts the 99th percentile of the white frame at 0.9 x 255 = 229.5 DN; whole
#: DN values can only come within 0.5 DN (measured 0.45 DN).
AUTO_EXPOSURE_LEVEL_DN = 1.0

# --- calib ------------------------------------------------------------------------------
#: issue requirements for the end-to-end calibration (default rig, noise-free, 4 spp); the
#: measured values are ~6x (RMS), ~25x (fx), ~3x (principal point), ~40x (baseline) and
#: ~6x (rotation) smaller, so these fail on any real regression.
CALIB_RMS_PX = 0.03
CALIB_FOCAL_REL = 5e-4
CALIB_PRINCIPAL_POINT_PX = 0.5
CALIB_BASELINE_M = 1e-4
CALIB_ROTATION_DEG = 0.01
#: detected (OpenCV blob) centres vs true centres: perspective bias (<= 0.16 px at 30 deg)
#: plus blob quantisation; a wrongly ordered grid is off by >= one spacing (> 25 px).
CALIB_DETECT_PX = 0.5
#: refined centroid vs exact area centroid of the circle's image on exact 3x3-supersampled
#: images with a 30 % illumination gradient: measured <= 0.012 px (the supersampling's own
#: edge quantisation); an unnormalised background would shift it by ~0.02 px.
CALIB_CENTROID_PX = 0.02
#: perspective bias of the paper's 30 deg poses: measured 0.05-0.16 px, i.e. above the
#: 0.03 px budget, which is why it is corrected.
CALIB_MIN_TILT_BIAS_PX = 0.03
#: local homography on exact projector coordinates: a plane induces an exact homography
#: (no distortion in the default rig), so only float rounding remains (measured ~1e-6 px).
CALIB_HOMOGRAPHY_EXACT_PX = 1e-4
#: same on coordinates rounded to whole projector pixels (a hard DMD staircase, +-0.5 px),
#: RMS over the circles of a pose: ~500 pixels per neighbourhood average it to 0.003-0.007
#: px (single circles reach 0.05 px where the camera and projector grids beat).
CALIB_HOMOGRAPHY_STAIRCASE_RMS_PX = 0.02
#: calibration from exact points: OpenCV's LM converges to ~1e-5 px RMS (float32 inputs).
CALIB_EXACT_RMS_PX = 1e-3
CALIB_EXACT_FOCAL_REL = 1e-6
CALIB_EXACT_PRINCIPAL_POINT_PX = 0.01
#: baseline and rotation of the same calibration from exact points: measured 5e-9 m and
#: 1.8e-5 deg.
CALIB_EXACT_BASELINE_M = 1e-6
CALIB_EXACT_ROTATION_DEG = 1e-4
#: printed board texture (blurred, 0.2 mm texels): total darkness vs n pi r^2; blur and
#: pixelisation preserve the area to measured 1.1e-5 relative.
CALIB_TEXTURE_AREA_REL = 1e-3
#: centroid of one circle's texels vs its centre: 1 % of the test's 0.2 mm texel; symmetric
#: pixelisation leaves measured 0.0014 texel (0.3 nm).
CALIB_TEXTURE_CENTROID_M = 2e-6
#: the paper's poses reach a 30 deg tilt: slack for float rounding in arccos (the largest
#: tilt measured is 33.2 deg, so it is never used).
CALIB_POSE_TILT_DEG = 1e-9
#: centroid bias of a fronto-parallel centred circle, which is zero in closed form: float64
#: rounding of the shoelace sums over the projected outline (measured 4e-13 px).
CALIB_FRONTO_PARALLEL_BIAS_PX = 1e-9
#: truth_error's rotation angle for a known 0.02 deg turn: atan2 form is well conditioned
#: (measured 1.3e-14 relative).
CALIB_TRUTH_ROTATION_REL = 1e-6
#: recalibrating from saved observations: the same float64 inputs, but OpenCV's threaded
#: reductions may sum in another order (measured differences 6e-12 in proj2cam entries).
CALIB_RECALIBRATE_ATOL = 1e-9
#: text files hold repr() floats; OpenCV YAML 17 significant digits: round trips are exact
#: to double rounding.
CALIB_FILE_ROUND_TRIP = 1e-12

# --- metrology --------------------------------------------------------------------------
#: sphere fit radius, RELATIVE to the true radius (issue: "within 1e-4 of truth"). 20k points
#: with 20 um noise and 30 % outliers: the statistical radius error is ~0.3 um (6e-6 rel), so
#: 1e-4 (5 um on 50 mm) leaves a wide margin yet fails for any biased estimator.
SPHERE_RADIUS_REL = 1e-4
#: sphere centre in the same test (metres); a biased fit moves it by far more than 5 um.
SPHERE_CENTRE_M = 5e-6
#: inlier ratio of that fit vs the true one: outliers inside the threshold band look like
#: inliers (measured <= 0.0015) ...
SPHERE_INLIER_RATIO_ABS = 0.01
#: ... while true inliers are all kept (measured recall >= 0.9999).
SPHERE_INLIER_RECALL_MIN = 0.97
#: inlier RMS vs the 20 um noise: sampling error of 20k residuals, measured <= 0.6 %.
SPHERE_RMS_REL = 0.1
#: spheres through 4 exact points: closed-form float64 solve, measured 4.5e-15 m.
FOUR_POINT_SPHERE_M = 1e-10
#: 1 - |n_fit . n_true| of plane fits to 5000 points (with and without 23 % outliers):
#: measured 5e-12 (a tilt of 3 urad; 1 - cos is quadratic in the tilt). 1e-9 allows 45 urad,
#: the angular noise of 5000 points with +-25 um scatter over a 0.2 m patch is ~3 urad.
PLANE_NORMAL_COS = 1e-9
#: robust flatness: outliers accepted inside the +-0.1 mm threshold band can stretch the
#: peak-to-valley up to the band's 2e-4 m width (measured 7e-5 m).
PLANE_ROBUST_FLATNESS_MAX_M = 2e-4
#: plane flatness (peak-to-valley) of 5000 uniform heights in +-25 um: the sample extremes
#: fall within ~0.1 % of the band, the TLS plane tilt adds ~1 %.
PLANE_FLATNESS_REL = 0.03
#: C2M of points sampled on the mesh itself, or 0.1 mm off it along the face normal (signed
#: distances): exact closest points give float rounding only (measured 5e-18 m off surface).
C2M_ON_SURFACE_M = 1e-9
#: ICP recovering a 2 deg / 3.6 mm transform from noise-free surface samples: converges to
#: ~1e-9; 1e-5 deg and 1 um leave room for the linearised steps' final rounding.
ICP_ROTATION_DEG = 1e-5
ICP_TRANSLATION_M = 1e-6
#: C2M MAE of the free-form object, single view and merged turntable (issue requirement:
#: 0.05 mm; measured 0.007 mm single view, 0.008 mm for 4-8 merged views, blurred projector).
C2M_MAE_M = 5e-5

# --- capture / import -------------------------------------------------------------------
#: decoded vs ground-truth projector coordinates of a rendered 12-bit capture with bilinear
#: projector pixels (160 px camera, 4 spp): as in the renderer's accuracy tests, the sample
#: grid's sub-pixel spread dominates (~0.003-0.005 px RMS measured on larger cameras);
#: 0.02 px is the issue's decoding requirement.
DECODE_RENDERED_BILINEAR_PX = 0.02
#: the lab sequence (binary 18-step fringes, N = 18): the square wave's aliased harmonics
#: 17 and 19 leave a phase error of ~1e-3 rad (~0.003 px at T = 18); 0.03 px leaves room
#: for the rendered sampling and still fails on any order or alignment error (>= 9 px).
DECODE_LAB_BINARY_PX = 0.03
#: share of decoded pixels flagged for a correct description of rendered frames (the issue
#: asks for > 20 % under a wrong description; a clean decode must stay far below it).
FLAGGED_SHARE_CLEAN = 0.005
#: median |depth error| of an imported capture reconstructed through the paper code's text
#: files (the txt round trip is exact to ~1e-15; the decode noise at 1 m is ~0.1 mm with
#: bilinear pixels on a 160 px camera).
IMPORTED_DEPTH_M = 5e-4

# --- calibration files ------------------------------------------------------------------
#: K read back from JSON, OpenCV YAML/XML (written with 17 significant digits) or text files
#: (repr): exact in float64 (measured 0); 1e-12 relative fails on any lost digit or swap.
CALIB_IO_K_REL = 1e-12
#: proj2cam.t read back, metres: mm -> m is a multiplication by 0.001 (inexact in binary)
#: and stereo files store X_proj = R X_cam + T, inverted as -R^T T: a few ulps of 0.1 m,
#: measured <= 3e-17 m. 1e-12 m fails on any unit slip (1e-3 relative) or sign error.
CALIB_IO_T_M = 1e-12
#: a rig composed from a camera pose and a projector pose in a board frame (some labs' text
#: folders): two float64 products of values of order 1 (R) and 0.1-1 m (t), ~1e-16.
CALIB_IO_COMPOSED = 1e-12

# --- pipeline.calibrate (the calibration job: resume, reproducibility) ------------------
#: focal length of the small job the resume tests run (paper rig at 1/4 resolution, 1 spp,
#: 4x7 board, 6 random poses, seed 5): measured -7.1e-5; it only shows the small
#: configuration still calibrates (a run that solved garbage would be off by > 1e-2).
CALIB_JOB_SMALL_FOCAL_REL = 1e-3

# --- sensor -----------------------------------------------------------------------------
#: photon transfer slope vs the system gain K (issue requirement 3 %; 12 levels x 131k
#: pixels give a variance estimate within ~0.4 % per level).
PHOTON_TRANSFER_SLOPE_REL = 0.03
#: photon transfer intercept vs K^2 sigma_d^2 + sigma_q^2 (issue requirement 10 %).
PHOTON_TRANSFER_INTERCEPT_REL = 0.10
#: measured phase noise vs sqrt(2/N) sigma_I / B (issue requirement 5 %; 65k pixels give
#: the standard deviation to ~0.3 %).
PHASE_NOISE_REL = 0.05

# --- render: light transport (tests/render/test_light_transport.py) ---------------------
#: band means (4 bands of 80 x 20 px) of multi-bounce frames in a 90 deg corner of albedo-0.9
#: walls vs Mitsuba's path tracer (64 spp each, different random paths): Monte Carlo noise of
#: ~100k paths per band, measured <= 0.6 % (bounces 2 and 3, white and a phase frame). The
#: task's 2 %; dropping the path throughput (albedo 0.9) is off by ~4 % near the corner.
INTERREFLECTION_MITSUBA_REL = 0.02
#: the corner's interreflections add to direct light (measured +43 % for 2 bounces, +59 %
#: for 3 in the middle bands); the task asks for > 10 %.
INTERREFLECTION_GAIN_MIN = 0.10
#: fitted blur diameter of a step edge (uniform-disk ESF, ~4000 pixels) vs the thin-lens
#: circle of confusion A f |d - d_f| / (d d_f): measured <= 0.3 % (projector, 16 x 16 taps
#: per pixel) and <= 0.4 % (camera, 64 spp); the task's 5 %. A radius used as a diameter
#: or a focus plane at the wrong depth is off by > 20 %.
DEFOCUS_BLUR_REL = 0.05
#: projector coordinates through the aperture of a lens focused on the plane vs the pinhole:
#: float32 rounding of a ~1 m geometry in projector pixels of ~0.5 mm (measured 2e-4 px).
FOCUSED_LENS_PX = 2e-3

# --- projector model --------------------------------------------------------------------
#: maximum gamma phase error vs the harmonic theory (0.291 / 1.06e-2 rad; issue: 5 %).
GAMMA_ERROR_REL = 0.05
#: share of the gamma error's energy in the N-times-frequency ripple (the large N = 3 error
#: has a 2N harmonic of ~2 % of its energy; 8-bit rounding adds ~1e-3 rad elsewhere).
GAMMA_RIPPLE_SHARE = 0.95
#: pre-compensation must lower the N = 3 gamma error at least this many times (issue: 20x).
PRECOMPENSATION_GAIN = 20.0
#: Gaussian PSF modulation factor vs exp(-2 pi^2 sigma^2 / P^2) (issue: 2 %).
PSF_MODULATION_REL = 0.02
#: mean phase shift of a symmetric blur (none in theory; the tabulated PSF's linear read-out
#: leaves ~1e-4 rad).
PSF_PHASE_SHIFT_RAD = 1e-3
#: largest phase deviation of sinusoidal fringes blurred by sigma = 3 px from the true phase:
#: the staircase's residue exp(-2 pi^2 sigma^2) is nil; the table's linear read-out and 8-bit
#: pattern levels leave ~2e-3 rad.
PSF_PHASE_SHIFT_MAX_RAD = 5e-3
#: binary fringes through a blurring lens vs their Fourier prediction (issue: 10 %).
BINARY_BLUR_REL = 0.10
#: band means (4 row and 4 column bands) of scene-light radiance (area panel + environment,
#: 1 and 2 bounces) vs Mitsuba with the projector black: Monte Carlo noise of both (64 and
#: 256 spp; uniform-sphere environment samples waste half their rays), measured <= 0.7 %.
LIGHTS_MITSUBA_REL = 0.02
#: mean radiance of an open plane under a constant environment vs rho L: 6400 px x 64 spp
#: of a per-sample relative noise ~0.33, i.e. 0.2 % standard error.
ENVIRONMENT_MEAN_REL = 0.01

# --- calibration from captures, checkerboards, twins, USD
# (tests/pipeline/test_calibrate_captures.py, tests/pipeline/test_twin.py,
# tests/twin/test_usd.py) -------------------------------------------------------------------
#: calibration from imported captures vs the rendered job on the same renders: the same
#: float64 observations through the same solver on one thread (measured exactly 0); the
#: issue's 1e-6 px and 1e-9 m.
REAL_EQUALS_VIRTUAL_PX = 1e-6
REAL_EQUALS_VIRTUAL_M = 1e-9
#: checkerboard calibration of the paper's rig at half resolution (480 x 480 camera), 10
#: random poses of a 6x9 board of 20 mm squares, 1 spp: focal lengths measured within
#: 1.6e-4 (the issue's 0.05 %), principal points 0.17 px, baseline 0.014 mm (issue 0.1 mm),
#: camera RMS 0.009 px (saddle-point corners).
CHECKER_FOCAL_REL = 5e-4
CHECKER_PRINCIPAL_POINT_PX = 0.5
CHECKER_BASELINE_M = 1e-4
CHECKER_RMS_PX = 0.03
#: USD round trips of metres: double transforms, unit shapes and float32 points that are
#: already float32 in the file; measured <= 2e-16 m (the issue's 1e-9 m).
USD_ROUND_TRIP_M = 1e-9
#: pixels through USD's float32 lens attributes (focalLength, apertures, offsets): ~6e-8
#: relative on values of ~1000 px from the image centre, measured 1.5e-5 px (metre stage)
#: and 9e-6 px (cm stage) with pxr's frustum; a wrong offset sign or half-pixel convention
#: is off by >= 0.5 px.
USD_FLOAT32_PX = 2e-4
#: twin validation, virtual to virtual (the twin read back from its USD stage, the true
#: board poses): the same renders, measured exactly 0 mm and 0 px; the issue's 0.01 mm
#: and 0.02 px.
TWIN_ROUND_TRIP_MAE_MM = 0.01
TWIN_ROUND_TRIP_PROJ_PX = 0.02
#: the same captures against a twin calibrated from them (quarter-resolution rig with
#: distortion, 4 poses, 1 spp): measured 0.016 mm MAE; it only shows the calibrated twin
#: lands on the captures (a wrong pose or rig convention is off by millimetres).
TWIN_CALIBRATED_MAE_MM = 0.1

# --- hardening: ground truth where two implementations are otherwise only compared -----
# (tests/patterns/test_decode_reliability.py, tests/render/jit/*.py, and others) -------
#: wrapped phase of ideal 8-bit frames (B / 2 = 90 DN) with as few as 4 steps: quantisation
#: (0.29 DN RMS) gives sigma_phi = 0.29 / 90 sqrt(2 / 4) = 2.3e-3 rad; measured max 0.012
#: rad over 5000 pixels (4 steps), 0.007 rad (5 steps and more). A sign or offset slip is
#: >= 0.5 rad, an order error 2 pi.
DECODE_PHASE_8BIT_FEW_STEPS_RAD = 0.02
#: the third path vertex's light alone (tests/render/test_light_transport.py), middle two
#: of 4 bands of the corner, vs Mitsuba's 3-bounce minus 2-bounce frames of one seed:
#: measured 0.1 % (the outer bands, where little light reaches a third vertex, 5 %). A path
#: throughput reset at each bounce (albedo 0.9) is off by +11 %.
INTERREFLECTION_THIRD_VERTEX_REL = 0.03
#: a camera lens focused on a textured board vs the pinhole (ambient light, albedo units):
#: each supersample's rays meet at one point of the board, so only float32 hit points and
#: the texture's bilinear read differ (measured 2.4e-5); a sphere of focus instead of
#: the plane blurs the 2 mm stripes 18 deg off axis by ~0.1.
FOCUSED_LENS_ALBEDO = 1e-3
#: mean relative radius error of the sphere fit (tests/metrology/test_metrology.py) over
#: SPHERE_BIAS_DRAWS independent draws of 20k points with 20 um noise and 30 % outliers:
#: one draw's error has a std of 4.7e-6 (measured over 20 draws, both estimators), so the
#: mean's is 1.9e-6 and 1e-5 is five of them. A radius biased by 3e-5, which the per-draw
#: requirement SPHERE_RADIUS_REL = 1e-4 lets through, is off by ten.
SPHERE_RADIUS_BIAS_REL = 1e-5
SPHERE_BIAS_DRAWS = 6
#: device-traced projector coordinates of a tilted plane vs the float64 ray-plane hit
#: projected through the distorted projector (tests/render/jit/test_tracing.py): Mitsuba
#: intersects in float32 (~1e-7 of ~1 m, i.e. ~2e-4 px at ~2300 px/m) and the projection
#: runs in float32 on the device (measured 4e-4 px); a half-pixel convention slip is 0.5 px.
DEVICE_TAP_PX = 5e-3

# --- twin photometry (tests/twin/test_photometric.py, tests/pipeline/test_twin.py) -------
#: every photometric parameter fitted back from virtual captures (gamma, blur, vignetting and
#: fall-off exponents, ambient, exposure, gain, dark noise) vs the truth (issue requirement
#: 5 %). Measured over 7 seeds (10-bit, three periods of 8 steps, three plane poses): gamma
#: +0.03..+0.07 %, blur +-0.3 %, exponents -0.7..+0.4 %, ambient +0.2 %, exposure 0.03 %,
#: gain -0.4..+0.2 %, dark noise +1.6..+3.4 % (its variance is 3 % of the captured levels').
PHOTOMETRIC_FIT_REL = 0.05
#: normalised noise-free frames of the fitted twin vs the original's, RMS (issue requirement
#: 1 %). Measured 0.03-0.07 % (8-bit single-period sequence with codes: up to 0.11 %).
PHOTOMETRIC_FRAME_RMS = 0.01
#: point noise (plane-fit RMS) of the original over the fitted twin's, minus 1 (issue
#: requirement 10 %). Measured -0.6..+0.4 % over 7 seeds (the std's sampling error with
#: ~50 000 points is 0.3 %).
PHOTOMETRIC_POINT_NOISE_REL = 0.1
#: the fit's harmonic model vs closed forms (blur factor, c_k / c_1 of x^2.2 of a cosine).
#: The 8-bit quantised pattern limits both: measured 5e-8 (blur), 6e-6 (m1), 1.0e-4 (q_3).
HARMONIC_THEORY = 1e-3
#: normalised frames of noisy board captures vs their twin with the fitted light (10-bit,
#: gain 0.128 DN/e-, mean white ~450 DN): the two captures' noise alone gives
#: sqrt(2 K / white) ~ 0.024 RMS; measured white 0.028, fringe 0.017 (3 poses). The
#: geometric twin (ideal projector) differs by 0.165 in the fringes, as real benches do.
TWIN_FITTED_FRAME_RMS = 0.04

# --- calibration conditioning and correspondences (tests/calib/test_conditioning.py,
# tests/calib/test_points.py) ---------------------------------------------------------------
#: reported standard deviation (first-order covariance at the solution) vs the spread over 20
#: noisy re-observations: the brief's factor 2. Measured ratios 1.14 (fx, face-on boards),
#: 1.21 (fx, spread boards); a 20-sample standard deviation alone is uncertain by ~16 %.
CONDITIONING_SIGMA_FACTOR = 2.0
#: k3 = 0.3 recovered by the k3 model on a wide-angle camera at 0.1 px noise: measured
#: 0.3007 with a reported sigma of 0.0009; the fixed model is off by the whole 0.3.
CALIB_K3_ABS = 0.01
#: fx of that camera with k3 free: measured 1.0e-4 relative; k3 fixed: 1.3e-2.
CALIB_K3_FOCAL_REL = 1e-3

# --- codes alone (tests/calib/test_observe_code_only.py) ---------------------------------
#: projector points of rendered boards observed from a Gray or binary code alone (quarter
#: rig, imx174, LightCrafter-class projector, 2 poses): mean error per axis measured
#: <= 0.0016 px; a half-pixel slip in the stripe-centre convention is 0.5 px.
CODE_ONLY_POINT_BIAS_PX = 0.01
#: their RMS error: measured 0.0051-0.0066 px (circles and checkerboard, Gray and binary;
#: 0.0093-0.0127 px with the phase's narrower neighbourhoods).
CODE_ONLY_POINT_RMS_PX = 0.01
#: ... against the decoded map read at the nearest camera pixel (0.33-0.35 px RMS): the
#: local homographies are measured ~50x closer.
CODE_ONLY_NAIVE_FACTOR = 10.0
#: 3.6 px Gray stripes (6 bits over 228 px): measured 0.093 px RMS; with a 1-px RANSAC
#: threshold every circle was lost.
CODE_ONLY_WIDE_STRIPE_RMS_PX = 0.25
#: noise of the mean of 8 pairs over that of (white + black) / 2 vs 1/sqrt(8): a standard
#: deviation over 4096 pixels is uncertain by ~1.1 %.
CODE_ONLY_UNIFORM_NOISE_REL = 0.1
#: Gray-code-only and binary-only benches calibrated from their captures
#: (tests/pipeline/test_calibrate_gray_only.py: 480 x 480 imx174 camera, 456 x 570
#: LightCrafter-class projector, 6 poses, 4 spp): the issue's requirements. Measured over
#: seeds 1-6 per code and board: fx and fy of both devices within 0.028 % (7x13 circles)
#: and 0.045 % (6x9 checkerboard; the test's seed 1 is that worst case), baselines within
#: 0.036 mm. The same poses with the 18-step phase sequence: 0.006 % and 0.047 %: the
#: checkerboard's corners (0.012 px RMS against the circles' 0.0035 px), not the code,
#: limit it.
CODE_ONLY_CALIB_FOCAL_REL = 5e-4
CODE_ONLY_CALIB_BASELINE_M = 1e-4
#: principal points: measured up to 0.37 px (circles) and 1.83 px (checkerboard; 1.61 px
#: with phase); a stripe-centre convention slip shows in tests/calib/test_observe_code_only.py.
CODE_ONLY_CALIB_PRINCIPAL_POINT_PX = {"circles": 1.0, "checker": 2.5}
#: rotation between the devices: measured up to 0.018 deg (phase: 0.009 deg).
CODE_ONLY_CALIB_ROTATION_DEG = 0.05

# --- learn ------------------------------------------------------------------------------
#: the torch phase -> depth layer vs virtus.reconstruct.triangulate(use="u") on random rigs
#: with distortion, float64: both solve the same ray-surface intersection (Newton to 1e-9 px
#: on a distorted projector, ~1e-12 m); 1e-6 m is the issue's bound and fails on a wrong
#: axis, sign, half pixel or a skipped distortion (millimetres).
LEARN_LAYER_M = 1e-6

# --- robot ------------------------------------------------------------------------------
#: forward kinematics of two implementations (virtus's tree, yourdfpy's scene graph) from
#: the same published parameters: ~10 4x4 products of order-1 values, rounding ~1e-15 m;
#: 1e-9 m is the issue's requirement and fails on any parameter, sign or frame error.
FK_AGREEMENT_M = 1e-9
#: analytic geometric Jacobian vs central differences with step 1e-6 rad: truncation
#: ~h^2 = 1e-12, rounding ~1e-16/1e-6 = 1e-10; 1e-7 fails on any wrong column or sign.
JACOBIAN_FD = 1e-7
#: inverse kinematics reaching a reachable target (issue requirement; the solver's own
#: tolerances are 1e-9 m / 1e-9 rad).
IK_POSITION_M = 1e-6
IK_ROTATION_RAD = 1e-6
#: noise-free hand-eye (issue requirement; closed form plus refinement reach ~1e-13).
HANDEYE_EXACT_RAD = 1e-6
HANDEYE_EXACT_M = 1e-6
#: hand-eye expected errors against the errors seen over seeded noisy trials: the 1-sigma
#: RSS prediction and the RMS of 20 draws agree within sampling error (~16 % for 20 draws
#: of a 3-d error); a factor 2 either way still fails a covariance off by sqrt(K) (points
#: of one pose share their pose's error), which was 4.5x here.
HANDEYE_EXPECTED_RATIO = 2.0

# --- uncertainty (predicted noise) --------------------------------------------------------
#: predicted vs Monte Carlo sigma at the median pixel (issue 23's bound). The median of
#: per-pixel standard deviations over 200 draws is itself within 0.2 % (measured 0.99-1.01
#: over the whole matrix of benchmarks/bench_uncertainty.py with 200 draws; 0.95-1.02 with 30).
MODEL_VS_MC_MEDIAN = 0.10
#: predicted vs Monte Carlo sigma at the raw 95th percentile (issue 23's bound, not
#: loosened). Part of it is the draws' own sampling spread, not model error: per-pixel stds of
#: n draws are sigma sqrt(chi2_{n-1} / (n - 1)), so on a constant sigma their 95th percentile
#: is lifted by sqrt(chi2_{n-1}(0.95) / (n - 1)) -- 1.18 for 40 draws (measured +19-20 % on a
#: plane), 1.082 for MODEL_VS_MC_DRAWS = 200 (MODEL_VS_MC_P95_SAMPLING): 8 of the 20 % go to
#: sampling where sigma is flat (less where it varies), 12 % are left for the model.
#: Measured over the bench's 36 cases with 200 draws: raw 0.99-1.07 (pooled 0.99-1.03).
MODEL_VS_MC_P95 = 0.20
#: noisy re-renders per Monte Carlo case (the issue asks >= 30; noise is re-applied to one
#: noise-free pass, so draws are cheap).
MODEL_VS_MC_DRAWS = 200
#: the raw 95th percentile's expected inflation by sampling spread at MODEL_VS_MC_DRAWS
#: draws (virtus.design.montecarlo.p95_sampling_inflation; scipy's chi2, to 1e-3).
MODEL_VS_MC_P95_SAMPLING = 1.082
#: first-order phase sigma vs 20,000 numpy draws (high SNR, B/sigma ~ 30: the linearisation
#: error is ~1e-3; the draws' sampling spread is 1/sqrt(2 x 20000) = 0.5 %; 3 % = 6 sigma).
PHASE_SIGMA_VS_DRAWS = 0.03
#: the EMVA variance vs 200,000 draws of the sensor's own model (0.3 % sampling spread).
EMVA_VARIANCE_VS_DRAWS = 0.015
#: design sweep scaling laws (sigma ~ 1/sqrt(N), ~ T) on identical geometry, N >= 4: the only
#: departures are the 8-bit pattern values and the staircase, measured < 0.5 % (N = 3's
#: phase-dependent sigma moves a median by up to 3 % when the period changes: not tested).
SWEEP_SCALING_REL = 0.02
