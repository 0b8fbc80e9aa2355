// Tests of input/elastic_sheet (issue 30); filled in as the module is built.
