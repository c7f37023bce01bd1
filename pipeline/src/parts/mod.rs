//! Body-part sets (SINC's six parts): parsing LLM answers, the embedded labeller, evaluation.
