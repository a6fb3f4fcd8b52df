//! The HTTP layer: router, errors, OpenAPI.
