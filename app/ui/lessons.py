"""The lessons on the page: a panel in the drawer with one button per lesson, and the open
lesson's card above the views (what to look at, why, what to try, a "Read more" text with its
maths drawn) with a "Leave lesson" button. The records and what opening one sets are
app.logic.lessons'."""

from __future__ import annotations

from trame.widgets import client, html
from trame.widgets import vuetify3 as v3

from app.logic import LESSONS
from app.ui.widgets import html_attributes

# a click on a card's glossary word (app.logic.words) opens the glossary at its entry
GLOSSARY_LINK = (
    "$event.target.dataset && $event.target.dataset.term && ($event.preventDefault(), "
    "glossary_term = $event.target.dataset.term, glossary_open = true)"
)


def lessons_panel() -> None:
    """The drawer's "Lessons" panel: a button per lesson (``open_lesson`` with its key)."""
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


def lesson_card() -> None:
    """The open lesson's card, above the views (nothing when no lesson is open): folded, one
    line; unfolded, what to look at, why, what to try and where to read more."""
    client.ClientStateChange(
        value="lesson",
        change="trame.utils.lmapdLesson && trame.utils.lmapdLesson.opened($event)",
        trigger_on_create=True,  # a lesson's link: its card may be there before this is
    )
    client.ClientStateChange(
        value="frame_key", change="trame.utils.lmapdLesson && trame.utils.lmapdLesson.frame()"
    )
    client.ClientStateChange(
        value="lesson_folded",
        change="trame.utils.lmapdLesson && trame.utils.lmapdLesson.folded($event)",
    )
    client.ClientStateChange(value="lesson", change="lesson_link_copied = ''")
    welcome_line()
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
                "Share",
                prepend_icon="mdi-link-variant",
                size="small",
                variant="text",
                click=(
                    "trame.utils.lmapdCopy(trame.utils.lmapdLink.url('lesson=' + lesson.key))"
                    ".then((m) => { lesson_link_copied = m; })"
                ),
                classes="share-lesson",
                **html_attributes(aria_label="Share this lesson (copy its link)"),
            )
            v3.VBtn(
                "Leave lesson",
                prepend_icon="mdi-close",
                size="small",
                variant="tonal",
                click="trigger('leave_lesson')",
                classes="leave-lesson",
            )
        html.Div(
            "{{ lesson_link_copied }}: whoever opens it gets this lesson, its card, views and "
            "selection",
            v_if="lesson_link_copied",
            classes="text-caption text-success px-4 lesson-link-copied",
            **html_attributes(role="status"),
        )
        with v3.VCardText(
            v_show="!lesson_folded", classes="pt-1 pb-2 lesson-body", click=GLOSSARY_LINK
        ):
            html.P(v_html=("lesson.basic_html",), classes="lesson-text lesson-basic")
            v3.VBtn(
                "{{ lesson_detail ? 'Less detail' : 'More detail' }}",
                prepend_icon=("lesson_detail ? 'mdi-chevron-up' : 'mdi-chevron-down'",),
                size="x-small",
                variant="text",
                color="primary",
                click="lesson_detail = !lesson_detail",
                classes="lesson-detail-button mb-1",
                **html_attributes(aria_expanded=("String(!!lesson_detail)",)),
            )
            with html.Div(v_show="lesson_detail", classes="lesson-detail"):
                for label, key in (("Look", "look"), ("Why", "why"), ("Try", "try_next")):
                    with html.P(classes=f"lesson-text lesson-{key.replace('_', '-')}"):
                        html.Span(f"{label}: ", classes="lesson-label")
                        html.Span(v_html=(f"lesson.{key}_html",))
            with html.P(classes="lesson-text lesson-reference text-caption mb-0"):
                html.Span("Read more: ", classes="lesson-label")
                html.A(  # the lesson's own text, its maths drawn, in a dialog
                    "{{ lesson.reference_title }}",
                    href="#read-more",
                    click="$event.preventDefault(); trigger('read_more', [lesson.key])",
                    classes="physics-link",
                )
            html.P(
                "{{ lesson.note }}",
                v_if="lesson.note",
                classes="lesson-text lesson-note text-deep-orange-darken-2 mb-0 mt-1",
            )


def physics_dialog() -> None:
    """A card's "Read more" (or the physics page's section it leads to) in a dialog
    (app.logic.physics_page): the text, its maths MathML, then the way to the full
    derivation."""
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
            v3.VCardText(v_html=("physics_section.html",), classes="physics-text")
            with html.Div(
                v_if="physics_section.kind === 'reader'", classes="px-4 pb-3 physics-more"
            ):
                html.Span("The full derivation, for those who want it: ", classes="text-caption")
                html.A(  # the documentation site's physics page, where one is configured
                    "the physics page of the documentation",
                    v_if="physics_section.docs_url",
                    href=("physics_section.docs_url",),
                    target="_blank",
                    rel="noopener",
                    classes="text-caption physics-docs-link",
                )
                html.A(  # else the page's section itself, in this dialog
                    "the physics page's section",
                    v_else_if="physics_section.full",
                    href="#physics",
                    click="$event.preventDefault(); "
                    "trigger('open_physics', [physics_section.anchor])",
                    classes="text-caption physics-full-link",
                )
                html.Span(
                    "the physics page of the documentation (docs/physics.md)",
                    v_else=True,
                    classes="text-caption",
                )


def welcome_line() -> None:
    """A first visit's one line (``trame.utils.lmapdWelcome``, set by app/static/link.js from
    this browser's storage): what the app is, "start here" (the first lesson) and, on a phone,
    where the controls are. Closing it, or opening a lesson, keeps it away."""
    first = LESSONS[0]
    with v3.VAlert(
        v_if="trame.utils.lmapdWelcome && !welcome_closed && !lesson",
        type="info",
        density="compact",
        variant="tonal",
        closable=True,
        click_close="trame.utils.lmapdLesson.welcomed()",
        classes="mb-2 welcome-line",
        __events=[("click_close", "click:close")],
        **html_attributes(role="status"),
    ):
        html.Span("Welcome: a laser camera in space, simulated. ")
        html.A(
            f"Start here: {first.title}",
            href="#start",
            click=f"$event.preventDefault(); trigger('open_lesson', ['{first.key}'])",
            classes="font-weight-bold start-here",
        )
        html.Span(
            " · the controls and the lessons are in the menu (☰, top left)",
            classes="d-md-none welcome-menu",
        )
