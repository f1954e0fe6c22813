"""The lessons on the page: a panel in the drawer with one button per lesson, and the open
lesson's card above the views (what to look at, why, what to try, the section to read) with a
"Leave lesson" button. The records and what opening one sets are app.logic.lessons'."""

from __future__ import annotations

from trame.widgets import client, html
from trame.widgets import vuetify3 as v3

from app.logic import LESSONS
from app.ui.widgets import html_attributes

CSS = """
.lesson-button.v-btn { height: auto !important; min-height: 30px; padding: 4px 10px;
  justify-content: flex-start; text-align: left; text-transform: none; letter-spacing: 0; }
.lesson-button .v-btn__content { white-space: normal; line-height: 1.3; }
.lesson-card { border-left: 4px solid #1565c0; position: sticky; top: 56px; z-index: 5;
  max-height: 45vh; overflow-y: auto; }
.lesson-head { flex-wrap: nowrap; overflow: hidden; }
.lesson-head .lesson-title, .lesson-head .lesson-view-name { white-space: nowrap;
  overflow: hidden; text-overflow: ellipsis; min-width: 0; }
.lesson-head .lesson-title { flex: 0 1 auto; }
.lesson-head .lesson-view-name { flex: 0 100 auto; }
.lesson-view { outline: 3px solid #ffb300; outline-offset: 2px; transition: outline-color 0.5s; }
@media (max-width: 600px) { .lesson-card { top: 48px; }
  .lesson-head { flex-wrap: wrap; }
  .lesson-head .lesson-title { white-space: normal; flex: 1 1 100%; } }
.lesson-card .lesson-text { font-size: 0.88rem; line-height: 1.45; margin-bottom: 4px; }
.lesson-card .lesson-label { font-weight: 600; color: #0d47a1; }
.lesson-card code { font-size: 0.8rem; }
.physics-text { font-size: 0.9rem; line-height: 1.5; }
.physics-text table { border-collapse: collapse; margin: 6px 0; }
.physics-text td, .physics-text th { border: 1px solid #e0e0e0; padding: 2px 6px; }
.physics-text code { font-size: 0.8rem; }
"""


def lessons_panel() -> None:
    """The drawer's "Lessons" panel: a button per lesson (``open_lesson`` with its key)."""
    client.Style(CSS)
    with v3.VExpansionPanels(variant="accordion", classes="mb-2 lessons-panel"):
        with v3.VExpansionPanel():
            v3.VExpansionPanelTitle(
                "Lessons (one-click scenes)", classes="text-body-2 lessons-title"
            )
            with v3.VExpansionPanelText():
                html.Div(
                    "Each sets the scene and selects pixels to look at; a card above the views "
                    "says what to see and why. Change anything, or leave the lesson, at any time.",
                    classes="text-caption hint mb-1",
                )
                for lesson in LESSONS:
                    v3.VBtn(
                        lesson.title,
                        block=True,
                        size="small",
                        variant=(f"lesson && lesson.key === '{lesson.key}' ? 'flat' : 'tonal'",),
                        color="primary",
                        click=f"trigger('open_lesson', ['{lesson.key}'])",
                        classes=f"lesson-button lesson-{lesson.key} mb-1",
                    )


# A lesson opened (the ``lesson`` state changed to a card): on a phone or a narrow window the
# drawer closes; on a short screen (under 1000 px) the card folds to one line (its title, the
# view it is about and a button to unfold it); the card stays at the top of the window while the
# page scrolls, and the view it names is brought into sight just below it, outlined for a few
# seconds (again when the lesson's frame arrives: a chart may grow meanwhile).
LESSON_SCRIPT = """
window.trame.utils.lmapdLesson = {
  pending: null,
  opened(lesson) {
    const state = window.trame.state;
    if (!lesson) { this.pending = null; return; }
    if (window.innerWidth < 960) state.set('main_drawer', false);
    if (lesson.view_selector === '.array-card') this.zoomTo(state.get('selected_pixels'));
    state.set('lesson_folded', window.innerHeight < 1000);
    this.pending = { selector: lesson.view_selector, until: performance.now() + 30000 };
    setTimeout(() => this.show(), 350);  // after the drawer's and the card's transitions
  },
  zoomTo(pixels) {  // the array image zoomed (at most 4x) about the lesson's pixels
    const n = (window.trame.state.get('array_image') || {}).pixels;
    if (!n || !pixels || !pixels.length) return;
    const rows = pixels.map((p) => p[0]), cols = pixels.map((p) => p[1]);
    const extent = Math.max(Math.max(...rows) - Math.min(...rows),
      Math.max(...cols) - Math.min(...cols)) + n / 8;
    const s = Math.min(4, Math.max(1, n / extent)), m = 1 - 1 / s;
    const u = (Math.max(...cols) + Math.min(...cols) + 1) / 2 / n;
    const v = (Math.max(...rows) + Math.min(...rows) + 1) / 2 / n;
    const clamp = (a) => Math.min(m, Math.max(0, a));
    window.trame.state.set('array_zoom', { s, x: clamp(u - 0.5 / s), y: clamp(v - 0.5 / s) });
  },
  frame() {
    if (this.pending && performance.now() < this.pending.until) setTimeout(() => this.show(), 50);
  },
  show() {
    if (!this.pending) return;
    const view = document.querySelector(this.pending.selector);
    const card = document.querySelector('.lesson-card');
    if (!view) return;
    const bar = document.querySelector('.v-app-bar');
    const above = (bar ? bar.getBoundingClientRect().bottom : 0)
      + (card ? card.getBoundingClientRect().height : 0) + 8;
    const top = view.getBoundingClientRect().top + window.scrollY - above;
    window.scrollTo({ top: Math.max(0, top), behavior: 'instant' });
    view.classList.add('lesson-view');
    clearTimeout(this.timer);
    this.timer = setTimeout(() => view.classList.remove('lesson-view'), 4000);
  },
};
"""


def lesson_card() -> None:
    """The open lesson's card, above the views (nothing when no lesson is open): folded, one
    line; unfolded, what to look at, why, what to try and where to read more."""
    client.Script(LESSON_SCRIPT)
    client.ClientStateChange(
        value="lesson", change="trame.utils.lmapdLesson && trame.utils.lmapdLesson.opened($event)"
    )
    client.ClientStateChange(
        value="frame_key", change="trame.utils.lmapdLesson && trame.utils.lmapdLesson.frame()"
    )
    with v3.VCard(
        v_if="lesson",
        classes=("['lesson-card mb-2', lesson_folded ? 'lesson-folded' : '']",),
        elevation=2,
        **html_attributes(role="region", aria_label="Lesson"),
    ):
        with v3.VCardTitle(classes="card-title d-flex align-center ga-2 lesson-head"):
            v3.VIcon("mdi-school-outline", color="primary", size="small")
            html.Span("Lesson: {{ lesson.title }}", classes="lesson-title")
            html.Span(
                "· look at {{ lesson.view }}",
                classes="lesson-view-name text-body-2 text-medium-emphasis",
            )
            v3.VSpacer()
            v3.VBtn(
                "{{ lesson_folded ? 'Show the card' : 'Fold' }}",
                prepend_icon=("lesson_folded ? 'mdi-chevron-down' : 'mdi-chevron-up'",),
                size="small",
                variant="text",
                click="lesson_folded = !lesson_folded",
                classes="fold-lesson",
                **html_attributes(aria_expanded=("String(!lesson_folded)",)),
            )
            v3.VBtn(
                "Leave lesson",
                prepend_icon="mdi-close",
                size="small",
                variant="tonal",
                click="trigger('leave_lesson')",
                classes="leave-lesson",
            )
        with v3.VCardText(v_show="!lesson_folded", classes="pt-1 pb-2 lesson-body"):
            for label, key in (("Look", "look"), ("Why", "why"), ("Try", "try_next")):
                with html.P(classes=f"lesson-text lesson-{key.replace('_', '-')}"):
                    html.Span(f"{label}: ", classes="lesson-label")
                    html.Span(f"{{{{ lesson.{key} }}}}")
            with html.P(classes="lesson-text lesson-reference text-caption mb-0"):
                html.Span("Read more: ", classes="lesson-label")
                html.A(  # the physics page's section, in a dialog
                    "{{ lesson.reference_title }}",
                    v_if="physics_available",
                    href=("'#' + lesson.reference.split('#')[1]",),
                    click="$event.preventDefault(); trigger('open_physics', [lesson.reference])",
                    classes="physics-link",
                )
                html.Span("{{ lesson.reference_title }}", v_else=True)
                html.Span(", ")
                html.Code("{{ lesson.reference }}")
                html.Span(" in the project's docs.")
            html.P(
                "{{ lesson.note }}",
                v_if="lesson.note",
                classes="lesson-text lesson-note text-deep-orange-darken-2 mb-0 mt-1",
            )


def physics_dialog() -> None:
    """The physics page's section a card's link opened (app.logic.physics_page)."""
    with v3.VDialog(
        model_value=("!!physics_section",),
        update_modelValue="$event || trigger('close_physics')",
        max_width=820,
        scrollable=True,
    ):
        with v3.VCard(
            v_if="physics_section",
            classes="physics-card",
            **html_attributes(role="region", aria_label="Physics page"),
        ):
            with v3.VCardTitle(classes="card-title d-flex align-center ga-2"):
                v3.VIcon("mdi-book-open-variant", color="primary", size="small")
                html.Span("{{ physics_section.title }}", classes="physics-title")
                v3.VSpacer()
                v3.VBtn(
                    icon="mdi-close",
                    size="small",
                    variant="text",
                    click="trigger('close_physics')",
                    **html_attributes(aria_label="Close the physics page"),
                )
            html.Div(
                "docs/physics.md#{{ physics_section.anchor }}",
                classes="text-caption hint px-4",
            )
            v3.VCardText(v_html=("physics_section.html",), classes="physics-text")
