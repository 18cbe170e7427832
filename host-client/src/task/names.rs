//! The upstream vocabulary: every setup step, getter and metric name a WAA
//! task may use. A name outside these lists fails when the task loads.
//! Whether this build *implements* a getter or metric is the evaluator
//! registry's business ([`crate::eval`]), reported by `arena validate`.

/// Setup step types (`config` and `evaluator.postconfig`): the 13 the corpus
/// uses and the ones upstream implements without using.
pub const SETUP_STEPS: &[&str] = &[
    "launch",
    "download",
    "sleep",
    "open",
    "activate_window",
    "execute",
    "command",
    "create_folder",
    "recycle_file",
    "chrome_open_tabs",
    "chrome_close_tabs",
    "update_browse_history",
    "update_browse_history_edge",
    "upload_file",
    "change_wallpaper",
    "close_window",
    "create_file",
    "close_all",
    "edge_open_tabs",
];

/// Result getter types (`evaluator.result[].type`), as upstream's `get_<type>` functions.
pub const RESULT_GETTERS: &[&str] = &[
    "vm_file", "vlc_config", "vm_command_line", "is_file_saved_desktop", "check_if_timer_started",
    "check_if_world_clock_exists", "url_dashPart", "vm_file_exists_in_vm_folder", "active_tab_info",
    "active_tab_url_parse", "all_png_file_names", "are_all_images_tagged", "are_files_sorted_by_modified_time",
    "bookmarks", "chrome_font_size", "cookie_data", "cookie_data_for_edge", "data_delete_automacally",
    "data_delete_automacally_from_edge", "default_search_engine", "default_search_engine_from_edge",
    "desktop_background", "edge_default_download_folder", "edge_font_size", "edge_home_page",
    "enable_do_not_track", "enable_do_not_track_from_edge", "enable_enhanced_safety_browsing",
    "enable_enhanced_safety_browsing_from_edge", "enabled_experiments", "favorites", "history",
    "history_for_edge", "image_dimension_matches_input", "is_all_docx_in_archive", "is_details_view",
    "is_directory_read_only_for_user", "is_file_desktop", "is_file_hidden", "is_files_moved_downloads",
    "is_red_circle_present_on_canvas", "night_light_state", "open_tabs_info", "page_info", "profile_name",
    "profile_name_from_edge", "shortcuts_on_desktop", "storage_sense_run_frequency", "system_notifications",
    "system_timezone", "url_shortcuts_on_desktop", "validate_pwa_installed", "vm_active_window_title",
    "vm_file_exists_in_desktop", "vm_folder_exists_in_documents", "vm_library_folders", "vm_wallpaper",
    "zipped_folder_in_desktop",
    // Used by upstream helpers and getters outside the corpus's result lists.
    "rule", "cloud_file", "pdf_from_url", "rule_relativeTime", "vm_screen_size", "accessibility_tree",
];

/// Expected getter types (`evaluator.expected[].type`).
pub const EXPECTED_GETTERS: &[&str] = &["rule", "cloud_file", "vm_file", "pdf_from_url", "rule_relativeTime"];

/// Metric names (`evaluator.func`).
pub const METRICS: &[&str] = &[
    "exact_match", "compare_table", "infeasible", "check_json_settings", "is_extension_installed",
    "compare_docx_files", "compare_text_file", "check_history_deleted", "check_json_keybindings",
    "check_qt_max_volume", "compare_images", "compare_line_spacing", "compare_pdfs", "is_cookie_deleted",
    "is_expected_bookmarks", "is_vlc_recordings_folder", "check_direct_json_object", "check_edge_font_size",
    "check_enabled_experiments", "check_font_size", "check_global_key_play_pause", "check_highlighted_words",
    "check_italic_font_size_14", "check_one_instance_when_started_from_file", "check_qt_bgcone",
    "check_qt_minimal_view", "check_qt_slider_colours", "check_qt_video_resize", "check_tabstops",
    "compare_audios", "compare_docx_tables", "compare_font_names", "compare_highlighted_text",
    "compare_subscript_contains", "compare_videos", "compare_zip_files", "evaluate_strike_through_last_paragraph",
    "find_default_font", "has_page_numbers_in_footers", "is_added_to_steam_cart", "is_expected_active_tab",
    "is_expected_tabs", "is_first_line_centered", "is_shortcut_on_desktop", "is_url_shortcut_on_desktop",
];
