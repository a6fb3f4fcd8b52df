//! (to be written)

use super::{EikonalError, EikonalOptions, EikonalOutput, EikonalProblem, InitialFront};
use crate::numerics::control::Control;

/// Solves the problem; see the module documentation.
pub(super) fn solve(
    _problem: &EikonalProblem<'_>,
    _front: &InitialFront,
    _options: &EikonalOptions,
    _control: &Control<'_>,
) -> Result<EikonalOutput, EikonalError> {
    Err(EikonalError::Option {
        field: "method",
        reason: "not implemented yet".into(),
    })
}
