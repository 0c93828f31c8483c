/*
 * hosek_eval.c: Hosek-Wilkie sky radiance from the coefficient arrays of
 * ArHosekSkyModelData_Spectral.h, ArHosekSkyModelData_CIEXYZ.h and ArHosekSkyModelData_RGB.h
 * (the published layout, as skyref.fit.export writes it). skyref's tests compile it against
 * exported headers and compare its output with the Python evaluator
 * (skyref.analytic.hosek.CoefficientTable.radiance).
 *
 * Build:  gcc -O2 -std=c99 -I <directory holding the three headers> hosek_eval.c -lm -o hosek_eval
 *
 * Input (stdin), one query per line:   kind channel elevation turbidity albedo theta gamma
 *   kind 0: spectral (channel 0..10 for 320..720 nm); 1: CIE XYZ; 2: RGB (channel 0..2).
 *   elevation: solar elevation; theta: view zenith angle; gamma: view-sun angle (radians).
 *   turbidity in [1, 10], albedo in [0, 1].
 * Output: one line per query, the radiance (%.17g) in the table's unit, clamped at 0 as the
 *   Python evaluator does (F is negative in a thin band at the horizon for some published values).
 */
#include <math.h>
#include <stdio.h>

#include "ArHosekSkyModelData_Spectral.h"
#include "ArHosekSkyModelData_CIEXYZ.h"
#include "ArHosekSkyModelData_RGB.h"

#define HALF_PI 1.57079632679489661923

enum { COEFFICIENTS = 9, CONTROL_POINTS = 6, TURBIDITIES = 10 };

/* The quintic Bernstein weights at x in [0, 1]. */
static void bezier_weights(double x, double weights[CONTROL_POINTS])
{
    static const double binomial[CONTROL_POINTS] = { 1.0, 5.0, 10.0, 10.0, 5.0, 1.0 };
    for (int k = 0; k < CONTROL_POINTS; ++k)
        weights[k] = binomial[k] * pow(x, k) * pow(1.0 - x, CONTROL_POINTS - 1 - k);
}

/*
 * Interpolate one configuration from a table laid out [albedo 2][turbidity 10][control point 6]
 * [stride]: linear in albedo, linear between the two neighbouring turbidities, Bezier in
 * x = (elevation / (pi/2))^(1/3), elevation clamped to [0, pi/2]. Writes `stride` values to out.
 */
static void interpolate(const double *table, int stride, double elevation, double turbidity,
                        double albedo, double *out)
{
    double weights[CONTROL_POINTS];
    double fraction = elevation / HALF_PI;
    bezier_weights(cbrt(fraction < 0.0 ? 0.0 : fraction > 1.0 ? 1.0 : fraction), weights);

    int lower = (int)floor(turbidity);          /* stored turbidities lower and lower + 1 */
    if (lower >= TURBIDITIES) lower = TURBIDITIES - 1;
    double above = turbidity - lower;           /* weight of lower + 1 */

    for (int i = 0; i < stride; ++i)
        out[i] = 0.0;
    for (int a = 0; a < 2; ++a) {
        double albedo_weight = a ? albedo : 1.0 - albedo;
        for (int j = 0; j < 2; ++j) {
            double weight = albedo_weight * (j ? above : 1.0 - above);
            const double *block = table + ((a * TURBIDITIES + lower - 1 + j) * CONTROL_POINTS) * stride;
            for (int k = 0; k < CONTROL_POINTS; ++k)
                for (int i = 0; i < stride; ++i)
                    out[i] += weight * weights[k] * block[k * stride + i];
        }
    }
}

/* F(theta, gamma) of coefficients stored A B C D E F G I H; views below the horizon see it. */
static double shape_function(const double c[COEFFICIENTS], double theta, double gamma)
{
    double cos_theta = cos(theta) > 0.0 ? cos(theta) : 0.0;
    double cos_gamma = cos(gamma);
    double sin_half = sin(0.5 * gamma);
    double h = c[8];
    /* 1 + H^2 - 2 H cos(gamma), written without cancellation near H = 1, gamma = 0 */
    double chi = (1.0 + cos_gamma * cos_gamma) / pow((1.0 - h) * (1.0 - h) + 4.0 * h * sin_half * sin_half, 1.5);
    double horizon = 1.0 + c[0] * exp(c[1] / (cos_theta + 0.01));
    return horizon * (c[2] + c[3] * exp(c[4] * gamma) + c[5] * cos_gamma * cos_gamma + c[6] * chi
                      + c[7] * sqrt(cos_theta));
}

int main(void)
{
    double **shapes[3] = { datasets, datasetsXYZ, datasetsRGB };
    double **radiances[3] = { datasetsRad, datasetsXYZRad, datasetsRGBRad };
    const int channels[3] = { 11, 3, 3 };
    int kind, channel;
    double elevation, turbidity, albedo, theta, gamma;

    while (scanf("%d %d %lf %lf %lf %lf %lf", &kind, &channel, &elevation, &turbidity, &albedo,
                 &theta, &gamma) == 7) {
        if (kind < 0 || kind > 2 || channel < 0 || channel >= channels[kind]
            || !(turbidity >= 1.0 && turbidity <= 10.0) || !(albedo >= 0.0 && albedo <= 1.0)) {
            fprintf(stderr, "hosek_eval: query out of range\n");
            return 1;
        }
        double coefficients[COEFFICIENTS], radiance;
        interpolate(shapes[kind][channel], COEFFICIENTS, elevation, turbidity, albedo, coefficients);
        interpolate(radiances[kind][channel], 1, elevation, turbidity, albedo, &radiance);
        radiance *= shape_function(coefficients, theta, gamma);
        printf("%.17g\n", radiance > 0.0 ? radiance : 0.0);
    }
    return 0;
}
