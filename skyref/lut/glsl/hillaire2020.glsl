// Hillaire 2020 sky and atmosphere LUTs: texture coordinates for the tables that
// `skyref export-lut` (skyref ${VERSION}) wrote beside this file; hillaire2020.json describes them.
// Lengths in metres; r is the distance from the planet's centre, mu the cosine of the view
// zenith angle, mu_s that of the sun's. Textures: linear filtering, clamp to edge, the EXR
// scanlines uploaded in order (no flip). The multiple-scattering and sky-view tables hold
// radiance per unit solar irradiance (sr^-1): multiply by the JSON's solar_irradiance.
// float32 note: r * r - R * R cancels within metres of the ground; keep r >= R + 1 m or use highp.

const float BOTTOM_RADIUS = ${BOTTOM_RADIUS};
const float TOP_RADIUS = ${TOP_RADIUS};
const int TRANSMITTANCE_WIDTH = ${TRANSMITTANCE_WIDTH};
const int TRANSMITTANCE_HEIGHT = ${TRANSMITTANCE_HEIGHT};
const int MULTIPLE_SCATTERING_WIDTH = ${MULTIPLE_SCATTERING_WIDTH};
const int MULTIPLE_SCATTERING_HEIGHT = ${MULTIPLE_SCATTERING_HEIGHT};
const int SKY_VIEW_WIDTH = ${SKY_VIEW_WIDTH};
const int SKY_VIEW_HEIGHT = ${SKY_VIEW_HEIGHT};
const float PI = 3.14159265358979;

uniform sampler2D transmittance_texture;
uniform sampler2D multiple_scattering_texture;
uniform sampler2D sky_view_texture;   // for one observer altitude and sun: see "sky_view" in the JSON

// Place x in [0, 1] on an axis of n texels so that x = 0 and x = 1 fall on the outer texel centres.
float on_texel_centres(float x, int n) {
  return 0.5 / float(n) + x * (1.0 - 1.0 / float(n));
}

// Transmittance table (Bruneton's parametrization): x along the width from the distance to the
// top between its least (straight up) and its most (towards the horizon), y from the distance
// to the ground's horizon.
vec2 transmittance_uv(float r, float mu) {
  float H = sqrt(TOP_RADIUS * TOP_RADIUS - BOTTOM_RADIUS * BOTTOM_RADIUS);
  float rho = sqrt(max(r * r - BOTTOM_RADIUS * BOTTOM_RADIUS, 0.0));
  float to_top = max(-r * mu + sqrt(max(r * r * (mu * mu - 1.0) + TOP_RADIUS * TOP_RADIUS, 0.0)), 0.0);
  float shortest = TOP_RADIUS - r;
  float longest = rho + H;
  return vec2(on_texel_centres((to_top - shortest) / (longest - shortest), TRANSMITTANCE_WIDTH),
              on_texel_centres(rho / H, TRANSMITTANCE_HEIGHT));
}

// Multiple-scattering table: sun zenith cosine along the width, altitude along the height, both affine.
vec2 multiple_scattering_uv(float r, float mu_s) {
  float x_r = clamp((r - BOTTOM_RADIUS) / (TOP_RADIUS - BOTTOM_RADIUS), 0.0, 1.0);
  return vec2(on_texel_centres(0.5 * mu_s + 0.5, MULTIPLE_SCATTERING_WIDTH),
              on_texel_centres(x_r, MULTIPLE_SCATTERING_HEIGHT));
}

// Sky-view table: the azimuth from the sun (cos_azimuth, of the horizontal projections) along the
// width, sin(phi / 2); the view zenith angle along the height, square-root spaced on both sides
// of the horizon, which sits at the middle row boundary.
vec2 sky_view_uv(float r, float mu, float cos_azimuth, bool ray_hits_ground) {
  float beta = acos(clamp(sqrt(max(r * r - BOTTOM_RADIUS * BOTTOM_RADIUS, 0.0)) / r, -1.0, 1.0));
  float horizon_zenith = PI - beta;
  float theta = acos(clamp(mu, -1.0, 1.0));
  float y = ray_hits_ground ? 0.5 * (1.0 + sqrt(max((theta - horizon_zenith) / beta, 0.0)))
                           : 0.5 * (1.0 - sqrt(max(1.0 - theta / horizon_zenith, 0.0)));
  float x = sqrt(max(0.5 * (1.0 - cos_azimuth), 0.0));
  return vec2(on_texel_centres(x, SKY_VIEW_WIDTH), on_texel_centres(y, SKY_VIEW_HEIGHT));
}
