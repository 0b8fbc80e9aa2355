// The layer's code is in proprio_openxr_layer_impl (linked whole into this
// module) so unit tests can link the very same code without the loader.
