// Placeholder while issue 30 is built; replaced by the module's code.
namespace proprio::elastic_sheet {}
