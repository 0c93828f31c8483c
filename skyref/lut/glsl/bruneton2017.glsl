// Bruneton 2017 precomputed atmospheric scattering: texture coordinates for the tables that
// `skyref export-lut` (skyref ${VERSION}) wrote beside this file; bruneton2017.json describes them.
// Lengths in metres; r is the distance from the planet's centre, mu the cosine of the view
// zenith angle, mu_s that of the sun's, nu that of the angle between view and sun.
// Textures: linear filtering, clamp to edge, the EXR scanlines uploaded in order (no flip).
// bruneton2017_scattering.exr (and _single_mie.exr) is a 3-D texture of
// NU_SIZE * MU_S_SIZE x MU_SIZE x R_SIZE texels whose depth slices the EXR stacks top-down:
// upload its pixels as they are with glTexImage3D.
// float32 note: r * r - R * R cancels within metres of the ground; keep r >= R + 1 m or use highp.

const float BOTTOM_RADIUS = ${BOTTOM_RADIUS};
const float TOP_RADIUS = ${TOP_RADIUS};
const float MU_S_MIN = ${MU_S_MIN};
const int TRANSMITTANCE_WIDTH = ${TRANSMITTANCE_WIDTH};
const int TRANSMITTANCE_HEIGHT = ${TRANSMITTANCE_HEIGHT};
const int R_SIZE = ${R_SIZE};
const int MU_SIZE = ${MU_SIZE};
const int MU_S_SIZE = ${MU_S_SIZE};
const int NU_SIZE = ${NU_SIZE};
const int IRRADIANCE_WIDTH = ${IRRADIANCE_WIDTH};
const int IRRADIANCE_HEIGHT = ${IRRADIANCE_HEIGHT};

uniform sampler2D transmittance_texture;
uniform sampler3D scattering_texture;   // RGB; A = single Mie of R when the JSON says combined_mie
uniform sampler3D single_mie_texture;   // only without combined_mie
uniform sampler2D irradiance_texture;

// Place x in [0, 1] on an axis of n texels so that x = 0 and x = 1 fall on the outer texel centres.
float on_texel_centres(float x, int n) {
  return 0.5 / float(n) + x * (1.0 - 1.0 / float(n));
}

// Length of the horizontal ray from the ground to the top of the atmosphere.
float ground_horizon_length() {
  return sqrt(TOP_RADIUS * TOP_RADIUS - BOTTOM_RADIUS * BOTTOM_RADIUS);
}

// Length of the ray from radius r along zenith cosine mu to the top of the atmosphere.
float length_to_top(float r, float mu) {
  float q = r * r * (mu * mu - 1.0) + TOP_RADIUS * TOP_RADIUS;
  return max(-r * mu + sqrt(max(q, 0.0)), 0.0);
}

// Transmittance table: x along the width from the distance to the top (between its least,
// straight up, and its most, towards the horizon), y from the distance to the ground's horizon.
vec2 transmittance_uv(float r, float mu) {
  float H = ground_horizon_length();
  float rho = sqrt(max(r * r - BOTTOM_RADIUS * BOTTOM_RADIUS, 0.0));
  float shortest = TOP_RADIUS - r;
  float longest = rho + H;
  float x_mu = (length_to_top(r, mu) - shortest) / (longest - shortest);
  return vec2(on_texel_centres(x_mu, TRANSMITTANCE_WIDTH), on_texel_centres(rho / H, TRANSMITTANCE_HEIGHT));
}

// Transmittance from (r, mu) to the top of the atmosphere (for rays that miss the ground).
vec3 transmittance_to_top(float r, float mu) {
  return texture(transmittance_texture, transmittance_uv(r, mu)).rgb;
}

// Fraction a of the way between the shortest (zenith) and the longest (horizon) sun ray from
// the ground to the top, for a sun at zenith cosine mu_s.
float sun_path_fraction(float mu_s) {
  float H = ground_horizon_length();
  float d = length_to_top(BOTTOM_RADIUS, mu_s);
  float shortest = TOP_RADIUS - BOTTOM_RADIUS;
  return (d - shortest) / (H - shortest);
}

// Coordinates (u_nu, u_mu_s, u_mu, u_r) of the 4-D scattering table. The mu axis is split at
// its middle: rays that hit the ground below it, the others above.
vec4 scattering_uvwz(float r, float mu, float mu_s, float nu, bool ray_hits_ground) {
  float H = ground_horizon_length();
  float rho = sqrt(max(r * r - BOTTOM_RADIUS * BOTTOM_RADIUS, 0.0));
  float u_r = on_texel_centres(rho / H, R_SIZE);
  float q = r * r * (mu * mu - 1.0) + BOTTOM_RADIUS * BOTTOM_RADIUS;
  float u_mu;
  if (ray_hits_ground) {
    float d = -r * mu - sqrt(max(q, 0.0));
    float shortest = r - BOTTOM_RADIUS;
    float x = rho == shortest ? 0.0 : (d - shortest) / (rho - shortest);
    u_mu = 0.5 - 0.5 * on_texel_centres(x, MU_SIZE / 2);
  } else {
    float d = -r * mu + sqrt(max(q + H * H, 0.0));
    float shortest = TOP_RADIUS - r;
    u_mu = 0.5 + 0.5 * on_texel_centres((d - shortest) / (rho + H - shortest), MU_SIZE / 2);
  }
  float a = sun_path_fraction(mu_s);
  float a_lowest = sun_path_fraction(MU_S_MIN);
  float u_mu_s = on_texel_centres(max(1.0 - a / a_lowest, 0.0) / (1.0 + a), MU_S_SIZE);
  return vec4(0.5 * (nu + 1.0), u_mu_s, u_mu, u_r);
}

// The 4-D lookup: nu has NU_SIZE slices side by side along the width; read the two slices
// around nu and blend them.
vec4 scattering_lookup(sampler3D table, vec4 uvwz) {
  float x = uvwz.x * float(NU_SIZE - 1);
  float slice = floor(x);
  vec3 lower = vec3((slice + uvwz.y) / float(NU_SIZE), uvwz.z, uvwz.w);
  vec3 upper = vec3((slice + 1.0 + uvwz.y) / float(NU_SIZE), uvwz.z, uvwz.w);
  return mix(texture(table, lower), texture(table, upper), x - slice);
}

// Irradiance table: both axes affine.
vec2 irradiance_uv(float r, float mu_s) {
  float x_r = (r - BOTTOM_RADIUS) / (TOP_RADIUS - BOTTOM_RADIUS);
  return vec2(on_texel_centres(0.5 * mu_s + 0.5, IRRADIANCE_WIDTH), on_texel_centres(x_r, IRRADIANCE_HEIGHT));
}

// Sky radiance (W m^-2 sr^-1 nm^-1) along a ray inside the atmosphere that misses the ground:
//   vec4 s = scattering_lookup(scattering_texture, scattering_uvwz(r, mu, mu_s, nu, false));
//   radiance = s.rgb * rayleigh_phase(nu) + single_mie * mie_phase(nu),
// single_mie from single_mie_texture, or extrapolated from s.a (see "mie_extrapolation" in the JSON).
float rayleigh_phase(float nu) {
  return 3.0 / (16.0 * 3.14159265358979) * (1.0 + nu * nu);
}
