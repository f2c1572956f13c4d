"""Triage in a browser, with real events: choosing a sort goes to its first frame and the title
shows that frame's sort key."""

from test_app_browser import browser, chromium, data, open_page, tab, wait_for_text, wait_until  # noqa: F401

from pnlviz.app.frameorder import worst_residual


def test_choosing_a_sort_in_the_page_goes_to_its_first_frame(data, browser, serve):  # noqa: F811
    app = serve(data)
    app._worker.join(timeout=240)  # the background pass over every frame has ended (slow under load)
    assert not app._worker.is_alive(), "the background pass did not end within 240 s"
    st = app.state
    assert len(st.triage.summaries()) == len(st.stems)
    worst_first = sorted(st.stems, key=lambda s: -worst_residual(st.triage.lookup(s)))
    page = open_page(browser, app, "focal")
    session = tab(app)
    session.queue.enqueue(lambda: session.goto(st.find(worst_first[-1])))  # the sort's last frame
    wait_until(lambda: session.stem == worst_first[-1])
    page.get_by_label("sort").click()
    page.get_by_role("option", name="residual (worst first)", exact=True).click()
    wait_until(lambda: session.stem == worst_first[0])
    key = worst_residual(st.triage.lookup(worst_first[0]))
    wait_for_text(page, f"sorted by worst residual {key:,.1f} px")
    wait_for_text(page, "1/3")
    page.close()
