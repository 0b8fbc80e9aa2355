// Tests of input/stretch_array_recon (issue 30); filled in as the module is built.
