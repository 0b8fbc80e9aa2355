// Tests of input/stretch_array_sim (issue 30); filled in as the module is built.
