"""The structures table's ``cv_rmse_one_step`` column says what the number is (audit D5): the regression
target is d(eq)/dt, so it is an equation error of the derivative, not a one-step prediction."""

from pipeline.report import view


def test_the_note_is_the_rows_own_words_and_a_run_from_before_the_key_gets_them_without_the_unit():
    said = "equation error of dx/dt, in m/s: RMS of the regression residual on the fold"
    s = {"structures": {"settings": {"equation": "x"}},
         "models": [{"name": "nominal", "cv_rmse_sim": None},
                    {"name": "M1", "cv_rmse_one_step": [0.1], "cv_rmse_one_step_measures": said}]}
    assert view.equation_error_note(s) == said
    old = {"structures": {"settings": {"equation": "h"}}, "models": [{"name": "M1", "cv_rmse_one_step": [0.1]}]}
    note = view.equation_error_note(old)
    assert note.startswith("equation error of dh/dt") and "not a one-step-ahead prediction of h" in note
