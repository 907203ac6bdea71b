/* zw_estimate: zwidth's velocity estimators from MATLAB or Octave, through
 * the C ABI (include/zwidth.h). MEX API only, so the same source builds
 * with MATLAB's `mex` and Octave's `mkoctfile --mex`:
 *
 *   mex -I../include zw_estimate.c ../../../target/release/libzwidth_ffi.a
 *   mkoctfile --mex -I../include zw_estimate.c ../../../target/release/libzwidth_ffi.a
 *
 * v = zw_estimate(spec, rate_hz, quantization_m, positions)
 *   spec            the JSON estimator spec the API takes, a char row:
 *                   '{"kind":"butterworth","cutoff_hz":100,"order":2}'
 *   rate_hz         the sample rate (Hz)
 *   quantization_m  the encoder step (m)
 *   positions       a real double vector of positions (m)
 *   v               the velocities (m/s), the shape of positions
 *
 * Bad input is an error naming the argument (identifier zwidth:...). */
#include <stddef.h>

#include "mex.h"
#include "zwidth.h"

/* 8 KiB: static storage, as in a Simulink DWork. */
static zw_estimator est;

static int real_double_scalar(const mxArray *a) {
    return mxIsDouble(a) && !mxIsComplex(a) && mxGetNumberOfElements(a) == 1;
}

void mexFunction(int nlhs, mxArray *plhs[], int nrhs, const mxArray *prhs[]) {
    (void)nlhs;
    if (nrhs != 4) {
        mexErrMsgIdAndTxt("zwidth:arguments",
                          "zw_estimate(spec, rate_hz, quantization_m, positions): 4 arguments, got %d",
                          nrhs);
    }
    if (!mxIsChar(prhs[0])) {
        mexErrMsgIdAndTxt("zwidth:spec", "spec must be a char row holding the JSON estimator spec");
    }
    if (!real_double_scalar(prhs[1]) || !real_double_scalar(prhs[2])) {
        mexErrMsgIdAndTxt("zwidth:sampling", "rate_hz and quantization_m must be real double scalars");
    }
    const mxArray *pos = prhs[3];
    if (!mxIsDouble(pos) || mxIsComplex(pos) || mxGetNumberOfDimensions(pos) != 2 ||
        (mxGetM(pos) > 1 && mxGetN(pos) > 1)) {
        mexErrMsgIdAndTxt("zwidth:positions", "positions must be a real double vector (m)");
    }
    char *spec = mxArrayToString(prhs[0]);
    if (spec == NULL) {
        mexErrMsgIdAndTxt("zwidth:spec", "spec could not be read as a string");
    }
    zw_error err;
    zw_status s = zw_init_json(&est, spec, mxGetScalar(prhs[1]), mxGetScalar(prhs[2]), &err);
    mxFree(spec);
    if (s != ZW_OK) {
        mexErrMsgIdAndTxt("zwidth:spec", "%s: %s", err.parameter, err.message);
    }
    size_t n = mxGetNumberOfElements(pos);
    plhs[0] = mxCreateDoubleMatrix(mxGetM(pos), mxGetN(pos), mxREAL);
    s = zw_step_n(&est, mxGetPr(pos), mxGetPr(plhs[0]), n);
    if (s == ZW_BAD_PARAMETER) {
        mexErrMsgIdAndTxt("zwidth:positions", "positions: every position must be a finite number (m)");
    }
    if (s != ZW_OK) {
        mexErrMsgIdAndTxt("zwidth:internal", "zw_step_n failed with status %d", (int)s);
    }
}
