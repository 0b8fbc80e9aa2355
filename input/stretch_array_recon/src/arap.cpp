// Placeholder while issue 30 is built; replaced by the module's code.
namespace proprio::stretch_array_recon {}
