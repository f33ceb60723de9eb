//! Two-arm closed-chain coordination (placeholder).
