//! Evaluation metrics (pending).
