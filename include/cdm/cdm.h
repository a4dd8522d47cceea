/*
 * cdm.h - the one public header of libcdm, the driver for the cable-driven
 * haptic master (four string pots, four cables to a holder, an IMU on the grip,
 * a Hall sensor on the jaw).
 *
 * Stable C ABI, major version 1 (SONAME libcdm.so.1).
 *
 * Conventions, for every function below:
 *  - Functions return an `int`: CDM_OK (0) or a negative `cdm_error`. Some
 *    return a negative code *and* fill their output (a stale or disconnected
 *    pose is still the last pose): each says so.
 *  - Handles are opaque, created and freed in pairs; every free accepts NULL.
 *  - Public structs begin with `uint32_t struct_size`, which the caller sets to
 *    sizeof(struct) before passing it in. The library writes only the fields
 *    that fit in that size, so a program built against 1.0 keeps working with
 *    1.x, where structs only ever grow at the end (new fields marked "since").
 *  - Lengths in mm, angles in rad, times in us (device) or ns (host,
 *    CLOCK_MONOTONIC). Device frame: the cable plane is y-z, x is out of the
 *    plane (the seed paper's frame, ../docs/protocol.md).
 *  - No global "current device". Detail text of an error lives per handle
 *    (cdm_device_error) or per thread (cdm_thread_error), never in a shared
 *    global.
 *  - Thread safety is written on every function. "Any thread" means the call
 *    may run concurrently with any other call on the same handle except
 *    cdm_close.
 */
#ifndef CDM_CDM_H
#define CDM_CDM_H

#include <stddef.h>
#include <stdint.h>

#if defined(_WIN32)
#  if defined(CDM_BUILDING_LIBRARY)
#    define CDM_API __declspec(dllexport)
#  else
#    define CDM_API
#  endif
#else
#  define CDM_API __attribute__((visibility("default")))
#endif

#ifdef __cplusplus
extern "C" {
#endif

#define CDM_VERSION_MAJOR 1
/* CMakeLists.txt's project(VERSION) is the one source; the configure step
 * fails when these differ from it, and tests/cli/test_abi_version.py checks the bindings' copies. */
#define CDM_VERSION_MINOR 2
#define CDM_VERSION_PATCH 0
#define CDM_VERSION_NUMBER (CDM_VERSION_MAJOR * 10000 + CDM_VERSION_MINOR * 100 + CDM_VERSION_PATCH)

/** "1.2.0": the version of the library actually loaded. Static text. Any thread. */
CDM_API const char *cdm_version(void);
/** CDM_VERSION_NUMBER of the library actually loaded. Any thread. */
CDM_API int cdm_version_number(void);

/* ------------------------------------------------------------------ errors */

/** Error codes. Values are pinned: they never change once released. */
typedef enum cdm_error {
    CDM_OK = 0,
    CDM_ERR_INVALID_ARG = -1,    /**< NULL pointer, bad size field, bad option value */
    CDM_ERR_NO_DEVICE = -2,      /**< no such device, or unknown URI scheme */
    CDM_ERR_IO = -3,             /**< the transport failed (hidapi, file) */
    CDM_ERR_TIMEOUT = -4,        /**< nothing arrived in time */
    CDM_ERR_DISCONNECTED = -5,   /**< device gone; the handle reconnects by itself */
    CDM_ERR_STALE = -6,          /**< the newest pose is older than the stale deadline */
    CDM_ERR_NO_DATA = -7,        /**< no report has arrived yet */
    CDM_ERR_PROTOCOL = -8,       /**< malformed or wrong-version report */
    CDM_ERR_UNSUPPORTED = -9,    /**< the transport or device cannot do this */
    CDM_ERR_NO_MEM = -10,
    CDM_ERR_PARSE = -11,         /**< malformed file (JSON, CSV, recording): see the detail text */
    CDM_ERR_NUMERIC = -12,       /**< no real solution, or a fit that did not converge */
    CDM_ERR_END_OF_STREAM = -13, /**< a replay or a scripted simulation has ended */
    CDM_ERR_CRC = -14,           /**< stored calibration failed its CRC */
    CDM_ERR_INTERNAL = -15,      /**< a bug in libcdm: please report it */
    CDM_ERR_CLOSED = -16,        /**< since 1.2: a wait ended by cdm_close or cdm_shutdown (no pose) */
    CDM_ERROR_COUNT = 17         /**< number of codes above, CDM_OK included */
} cdm_error;

/** Static English text for a code (unknown codes get "unknown error"). Any thread. */
CDM_API const char *cdm_strerror(int code);

/**
 * Detail text of the last failing call made by *this thread* (for calls that
 * have no handle, such as cdm_open or cdm_calibration_load): names what was
 * wrong and where (file, line, column; URI option). Valid until this thread's
 * next cdm_* call. Empty string when there is none.
 */
CDM_API const char *cdm_thread_error(void);

/** since 1.1: levels of cdm_set_log_fn's messages. */
typedef enum cdm_log_level {
    CDM_LOG_DEBUG = 0,   /**< every failing call's detail text (as cdm_thread_error) */
    CDM_LOG_INFO = 1,    /**< state changes: disconnections, reconnections, end of stream */
    CDM_LOG_WARNING = 2, /**< data problems that were handled: malformed reports, a truncated replay */
    CDM_LOG_ERROR = 3    /**< a device that cannot be reached, an internal error */
} cdm_log_level;

typedef void (*cdm_log_fn)(void *user, int level, const char *message);

/**
 * since 1.1. Routes libcdm's messages into the application's log: one
 * process-wide function (NULL: none, the default), called from whichever
 * thread the message arises on (reader threads, the caller's), never from
 * cdm_get_pose. Since 1.2 no library lock is held while it runs, so it may
 * be called concurrently from several threads (it must be thread-safe) and
 * may call any cdm_* function, cdm_close included (on a device's reader
 * thread that close is deferred, see cdm_close). A flood of malformed
 * reports is logged at the 1st, 10th, 100th, ... only. The message is
 * valid only during the call. cdm_set_log_fn returns once no call of the
 * previous function is running on another thread.
 */
CDM_API void cdm_set_log_fn(cdm_log_fn fn, void *user);

/* ----------------------------------------------------------------- records */

/** Pose flags (cdm_pose.flags). */
enum cdm_pose_flag {
    CDM_POSE_STALE = 1u << 0,            /**< older than the stale deadline */
    CDM_POSE_DISCONNECTED = 1u << 1,     /**< device gone: last good pose, held */
    CDM_POSE_COMPENSATED = 1u << 2,      /**< a loaded calibration was applied */
    CDM_POSE_OUT_OF_WORKSPACE = 1u << 3, /**< lengths had no real solution: last good position, held */
    CDM_POSE_END_OF_STREAM = 1u << 4,    /**< replay or scripted simulation finished */
    /** since 1.1: no position was ever computed (every report so far was out
     *  of the workspace); position is (0,0,0) and meaningless, the call
     *  returns CDM_ERR_NO_DATA. Orientation, grip and buttons are the newest. */
    CDM_POSE_NO_POSITION = 1u << 5
};

/** Button bits (cdm_pose.buttons). */
enum cdm_button {
    CDM_BUTTON_CLUTCH = 1u << 0, /**< thumb button; teleop clutch by convention */
    CDM_BUTTON_AUX = 1u << 1,
    CDM_BUTTON_MARK = 1u << 2    /**< "sample here": a jig session marks seated positions with it */
};

/**
 * The master's state, as a generic haptic input device. Size 104 (1.0),
 * 136 (1.1).
 * Set struct_size = sizeof(cdm_pose) before the call.
 */
typedef struct cdm_pose {
    uint32_t struct_size;
    uint32_t flags;            /**< cdm_pose_flag bits */
    double position[3];        /**< holder centre, mm, device frame (x out of the cable plane) */
    double orientation[4];     /**< grip orientation, unit quaternion w,x,y,z (IMU) */
    double grip;               /**< jaw opening, rad (0 = closed) */
    uint32_t buttons;          /**< cdm_button bits */
    uint32_t sequence;         /**< device report counter (wraps at 2^32) */
    uint64_t device_time_us;   /**< device clock at sampling */
    uint64_t host_time_ns;     /**< CLOCK_MONOTONIC when the report was received */
    uint32_t dropped;          /**< reports lost so far (sequence gaps, disconnections) */
    uint32_t reserved0;        /**< zero */
    /** since 1.1 (size 112): poses this handle has published so far, counted
     *  on the host (1 for the first); monotonic, never reset by the device or
     *  a reconnection. 0: no pose yet. Pass it to cdm_wait_pose_after. */
    uint64_t host_sequence;
    /** since 1.1 (size 136): holder velocity, mm/s, device frame: the
     *  backward difference of successive positions over the device clock
     *  through a first-order low-pass at 50 Hz (about 3.7 ms of lag at
     *  1 kHz: docs/protocol.md, "Velocity"). Zero until two positions, after
     *  a gap over 50 ms, and while the position is held (out of workspace). */
    double velocity[3];
} cdm_pose;

/** Raw sensor values of the newest report. Size 80 (1.0). */
typedef struct cdm_raw {
    uint32_t struct_size;
    uint32_t status;           /**< device status bits, as in the report (docs/protocol.md) */
    uint16_t pot_adc[4];       /**< string-pot ADC counts, cables 1..4 */
    uint16_t hall_adc;         /**< jaw Hall sensor ADC counts */
    uint16_t buttons;          /**< button bits, as in the report */
    int16_t quat_q14[4];       /**< IMU quaternion w,x,y,z, 1/16384 units */
    uint32_t sequence;
    double lengths_mm[4];      /**< pot_adc through each pot's nominal scale and offset */
    uint64_t device_time_us;
    uint64_t host_time_ns;
} cdm_raw;

/** What a device says about itself (feature report 0x02, or the simulation). Size 456 (1.0). */
typedef struct cdm_device_info {
    uint32_t struct_size;
    uint16_t vendor_id;
    uint16_t product_id;
    char uri[256];             /**< a URI that cdm_open accepts for this device */
    char serial[32];
    char firmware[16];         /**< "major.minor.patch" */
    char transport[16];        /**< "hid", "sim" or "replay" */
    uint32_t protocol_version;
    uint32_t adc_bits;         /**< resolution of the pot ADCs */
    double pot_scale_mm[4];    /**< mm per ADC count, cables 1..4 */
    double pot_offset_mm[4];   /**< mm at ADC count 0 */
    double a_mm, b_mm, m_mm;   /**< nominal geometry (the seed's a, b, m) */
    double report_rate_hz;     /**< nominal report rate */
    double hall_closed;        /**< Hall counts with the jaw closed */
    double hall_open;          /**< Hall counts with the jaw fully open */
    double grip_open_rad;      /**< jaw angle when fully open */
} cdm_device_info;

/* ----------------------------------------------------------- enumeration */

typedef struct cdm_device_list cdm_device_list;

/**
 * Lists the connected masters (hidapi, VID/PID of docs/protocol.md). An empty
 * list is not an error. Free with cdm_device_list_free. Any thread.
 */
CDM_API int cdm_enumerate(cdm_device_list **out);
CDM_API size_t cdm_device_list_count(const cdm_device_list *list);
/** Copies entry i into *info (struct_size set by the caller). */
CDM_API int cdm_device_list_get(const cdm_device_list *list, size_t i, cdm_device_info *info);
CDM_API void cdm_device_list_free(cdm_device_list *list);

/* ---------------------------------------------------------------- devices */

typedef struct cdm_device cdm_device;

/** One report as it arrives, handed to a sample callback. */
typedef struct cdm_sample {
    uint32_t struct_size;
    uint32_t report_len;
    const uint8_t *report;     /**< the input report's bytes, report ID first */
    const cdm_raw *raw;
    const cdm_pose *pose;
    /** since 1.1 (size 40): when the report was first received, ns: for
     *  replay: the host time recorded with it (so a replay recorded again,
     *  or exported, keeps its times); otherwise raw->host_time_ns. */
    uint64_t source_time_ns;
} cdm_sample;

/**
 * Called on the device's reader thread for every parsed report, in order.
 * It must return quickly at real-time rates; with `sim:?realtime=0` or
 * `replay:FILE?speed=0` it paces the stream (nothing is dropped).
 * The pointers are valid only during the call. The same rules as
 * cdm_event_fn for what it may call (cdm_close of its own device is
 * deferred; a cdm_wait_pose* on it returns CDM_ERR_INVALID_ARG at once).
 */
typedef void (*cdm_sample_fn)(void *user, const cdm_sample *sample);

/** since 1.1: what happened to an open device (cdm_event.kind). */
typedef enum cdm_event_kind {
    CDM_EVENT_DISCONNECTED = 1, /**< the device went away; the handle retries by itself */
    CDM_EVENT_RECONNECTED = 2,  /**< it is back (same serial) and streaming */
    CDM_EVENT_STALE = 3,        /**< no report for longer than the stale timeout */
    CDM_EVENT_FRESH = 4,        /**< reports again after STALE */
    CDM_EVENT_END_OF_STREAM = 5 /**< a replay or a scripted simulation ended */
} cdm_event_kind;

/** since 1.1: one device event. Valid only during the callback. */
typedef struct cdm_event {
    uint32_t struct_size;
    uint32_t kind;          /**< cdm_event_kind */
    uint64_t host_time_ns;  /**< CLOCK_MONOTONIC when the reader noticed it */
    const char *text;       /**< what happened, in words (never NULL) */
} cdm_event;

/**
 * since 1.1. Called on the device's reader thread when the device's state
 * changes (cdm_open_options.on_event). STALE is noticed within the stale
 * timeout plus 50 ms (the reader's poll). Keep it short; it may call any
 * cdm_* function. cdm_close of its own device is deferred (see cdm_close):
 * the handle is freed when the callback returns, and no callback of that
 * device starts after the cdm_close. cdm_wait_pose and cdm_wait_pose_after
 * on its own device return CDM_ERR_INVALID_ARG at once (no pose can arrive
 * while the reader thread waits; use cdm_get_pose). docs/reliability.md,
 * "Callbacks", has the table of what each callback may call.
 */
typedef void (*cdm_event_fn)(void *user, const cdm_event *event);

/** since 1.2: why the reader discarded a report (cdm_rejected.kind). */
typedef enum cdm_rejected_kind {
    CDM_REJECTED_MALFORMED = 1,   /**< the protocol parser refused it (cdm_stats.malformed) */
    CDM_REJECTED_OUT_OF_ORDER = 2 /**< a duplicate or a late report (cdm_stats.out_of_order) */
} cdm_rejected_kind;

/** since 1.2: a report the reader received and discarded. Valid only
 *  during the callback. */
typedef struct cdm_rejected {
    uint32_t struct_size;
    uint32_t kind;            /**< cdm_rejected_kind */
    const uint8_t *report;    /**< the bytes as received, report ID first */
    uint32_t report_len;
    uint32_t reserved0;
    /** when it was first received, ns (as cdm_sample.source_time_ns) */
    uint64_t source_time_ns;
    const char *reason;       /**< in words (never NULL) */
} cdm_rejected;

/**
 * since 1.2. Called on the device's reader thread, in arrival order with
 * the samples, for every report the reader discarded, so that a recorder
 * keeps every report the device sent (cdm_recorder_write_rejected). The
 * same rules as cdm_sample_fn.
 */
typedef void (*cdm_rejected_fn)(void *user, const cdm_rejected *rejected);

/** Options for cdm_open_ex. Zero-initialise, set struct_size. Size 24 (1.0), 32 (1.1), 40 (1.2). */
typedef struct cdm_open_options {
    uint32_t struct_size;
    uint32_t stale_timeout_us;  /**< 0: the default, 50000 */
    cdm_sample_fn on_sample;    /**< optional; installed before the first report */
    void *user;                 /**< passed to on_sample, on_event and on_rejected */
    cdm_event_fn on_event;      /**< since 1.1, optional: state changes (cdm_event_kind) */
    cdm_rejected_fn on_rejected; /**< since 1.2, optional: the reports discarded */
} cdm_open_options;

/**
 * Opens a master. URIs:
 *  - NULL or "": $CDM_DEVICE if set, else the first real device found.
 *  - "hid:/dev/hidrawN" or "/dev/hidrawN": a hidraw path.
 *  - "serial:SN" or "hid:serial=SN": the device with that serial number.
 *  - "sim:" or "sim:?opt=v&...": the in-process simulated master (options in
 *    docs/protocol.md: rate, noise, seed, motion, effects, device, realtime...).
 *  - "replay:FILE" or "replay:FILE?speed=0": a recording made by `cdm record`.
 * The reader thread starts before this returns. On failure *out is NULL and
 * cdm_thread_error() names what was wrong. Any thread.
 */
CDM_API int cdm_open(const char *uri, cdm_device **out);
CDM_API int cdm_open_ex(const char *uri, const cdm_open_options *options, cdm_device **out);

/**
 * Stops the reader thread and frees the handle. NULL is fine.
 * - Calls of cdm_wait_pose / cdm_wait_pose_after on this handle already in
 *   progress on other threads return CDM_ERR_CLOSED (no pose: *out zeroed,
 *   orientation the identity) and cdm_close frees the handle only once
 *   they have returned. Any other call must not run concurrently with it,
 *   and none may start once it has begun (a binding serialises this: see
 *   cdm_shutdown).
 * - From the device's own reader thread (its on_sample or on_event
 *   callback, or the log sink called there) the close is deferred, never a
 *   self-join: the waits in progress are woken as above, no further
 *   callback of this device starts, and the reader thread frees the handle
 *   as soon as the running callback returns. The call then leaves
 *   cdm_thread_error() reading "cdm_close: deferred: ..." (cdm_close
 *   returns no code: its 1.0 signature is void). The handle must not be
 *   used after the call, there as anywhere.
 */
CDM_API void cdm_close(cdm_device *dev);

/**
 * since 1.2. The first half of cdm_close, for bindings whose handles stay
 * valid while a call is in progress (C#'s SafeHandle, Python's reference
 * count): every cdm_wait_pose / cdm_wait_pose_after in progress on the
 * handle, and every later one, returns CDM_ERR_CLOSED at once with no pose.
 * The handle stays valid (cdm_get_pose and the other calls keep working)
 * until cdm_close frees it. Idempotent. Any thread, callbacks included.
 * CDM_ERR_INVALID_ARG for NULL.
 */
CDM_API int cdm_shutdown(cdm_device *dev);

/**
 * Copies the newest pose. Real-time safe: no allocation, no blocking, no lock
 * the reader thread can hold (a sequence lock; it retries only while a write
 * is under way, which takes well under a microsecond). Any thread, at 1 kHz
 * or faster.
 * Returns CDM_OK; or, with *out still filled with the last pose:
 * CDM_ERR_DISCONNECTED (flag DISCONNECTED), CDM_ERR_END_OF_STREAM,
 * CDM_ERR_STALE (flag STALE: older than the stale deadline). Returns
 * CDM_ERR_NO_DATA, *out zeroed but for struct_size, before the first report.
 * Never hands out a NaN: an unsolvable report keeps the last good position
 * and sets OUT_OF_WORKSPACE; before the first solvable report there is none
 * to keep: CDM_ERR_NO_DATA with OUT_OF_WORKSPACE | NO_POSITION (since 1.1).
 * The orientation is always a unit quaternion (identity before the first
 * report). On any return but CDM_OK, cdm_thread_error() says why (a
 * constant text: nothing is allocated); after CDM_OK it is empty.
 */
CDM_API int cdm_get_pose(cdm_device *dev, cdm_pose *out);

/**
 * Blocks until a pose newer than the newest at the time of the call arrives,
 * or timeout_ms passes (CDM_ERR_TIMEOUT; *out then holds the newest pose).
 * timeout_ms < 0 waits without limit. Same returns as cdm_get_pose. Any
 * thread but the device's own reader thread (its callbacks), where it
 * returns CDM_ERR_INVALID_ARG at once. CDM_ERR_CLOSED (no pose) when
 * cdm_close or cdm_shutdown ends the wait or came before it (since 1.2).
 */
CDM_API int cdm_wait_pose(cdm_device *dev, int timeout_ms, cdm_pose *out);

/**
 * since 1.1. Waits for a pose whose host_sequence is greater than
 * after_host_sequence: returns at once if one was already published (no
 * wake-up is lost between two calls), else blocks until one is or
 * timeout_ms passes (CDM_ERR_TIMEOUT, *out the newest pose). timeout_ms < 0
 * waits without limit; 0 only looks. Pass 0 to get the first pose. Returns
 * at once with CDM_ERR_END_OF_STREAM once a replay has ended. Same other
 * returns as cdm_get_pose. out->struct_size must cover host_sequence (112).
 * Any thread but the device's own reader thread (its callbacks), where it
 * returns CDM_ERR_INVALID_ARG at once. CDM_ERR_CLOSED as cdm_wait_pose.
 */
CDM_API int cdm_wait_pose_after(cdm_device *dev, uint64_t after_host_sequence, int timeout_ms, cdm_pose *out);

/** Raw values of the newest report. Same returns as cdm_get_pose. Any thread; does not block. */
CDM_API int cdm_get_raw(cdm_device *dev, cdm_raw *out);

/** Device information. Any thread. */
CDM_API int cdm_get_info(cdm_device *dev, cdm_device_info *out);

/** A pose older than this (host clock) is flagged stale. 0 restores the default (50 ms). Any thread. */
CDM_API int cdm_set_stale_timeout(cdm_device *dev, uint32_t timeout_us);

/** Counters of the reader thread. Size 48 (1.0), 72 (1.1), 80 (1.2). */
typedef struct cdm_stats {
    uint32_t struct_size;
    uint32_t reserved0;
    uint64_t reports;          /**< reports parsed and published */
    uint64_t malformed;        /**< reports rejected by the parser */
    uint64_t dropped;          /**< sequence gaps */
    uint64_t out_of_workspace; /**< reports whose lengths had no solution */
    uint64_t reconnects;       /**< successful reconnections after an unplug */
    /** since 1.1: sequence-counter discontinuities (a backward
     *  jump, or a forward jump larger than the reports the device could have
     *  sent since the last one, docs/protocol.md): a reset or a corrupted
     *  counter. Not counted in dropped. */
    uint64_t sequence_jumps;
    /** since 1.1: reports discarded because their sequence number was the
     *  newest one's (duplicate) or up to 64 behind it (arrived late). */
    uint64_t out_of_order;
    /** since 1.1: bytes of an incomplete last record a replay dropped (a
     *  recording cut by a kill or a full disk); 0 otherwise. */
    uint64_t replay_truncated_bytes;
    /** since 1.2: the device restarted its counter (a firmware restart or
     *  a brown-out, docs/protocol.md "Sequence numbers"): a backward step to
     *  a number the device could have counted to from 0 since the last
     *  report. Not counted in sequence_jumps; the numbers below the new one
     *  are counted in dropped. */
    uint64_t restarts;
} cdm_stats;

/** Any thread. */
CDM_API int cdm_get_stats(cdm_device *dev, cdm_stats *out);

/**
 * Detail text of the handle's last asynchronous problem (reader thread: a
 * malformed report, an unplug, a failed reconnection), copied into buf
 * (always NUL-terminated, truncated to len). Any thread.
 */
CDM_API int cdm_device_error(cdm_device *dev, char *buf, size_t len);

/* ------------------------------------------------------------ calibration */

/**
 * A fitted calibration: nominal geometry plus physical effects with their
 * parameters (`cdm calib fit` writes it as JSON, docs/calibration.md).
 */
typedef struct cdm_calibration cdm_calibration;

/**
 * Loads a calibration JSON file. Errors name the file, line and column. Any
 * thread. Checked on load (docs/calibration.md, "Checks on load"): the
 * schema (cdm-calibration version 1: unknown keys are refused, at any level,
 * with a "did you mean"), each parameter within its effect's bounds, and
 * the calibrated model over the workspace: at 27 points of it every
 * position the model gives for the nominal cable lengths must be finite and
 * within 20 % of min(a_mm, b_mm) of the point, whatever the parameters
 * (CDM_ERR_PARSE naming the point and the shift otherwise).
 */
CDM_API int cdm_calibration_load(const char *path, cdm_calibration **out);
/** The same from text in memory. */
CDM_API int cdm_calibration_parse(const char *json, size_t len, cdm_calibration **out);
CDM_API void cdm_calibration_free(cdm_calibration *cal);

/**
 * Corrected forward kinematics: the holder position (device frame, mm) whose
 * predicted readings best match `lengths_mm` (the pots' nominal-scale
 * readings). CDM_ERR_NUMERIC, position untouched, when there is no solution.
 * Does not allocate. Any thread; cal is read-only.
 */
CDM_API int cdm_calibration_position(const cdm_calibration *cal, const double lengths_mm[4],
                                     double position_mm[3]);

/** The inverse: the readings the calibrated model predicts at a position. */
CDM_API int cdm_calibration_lengths(const cdm_calibration *cal, const double position_mm[3],
                                    double lengths_mm[4]);

/** Number of effects in the calibration, and the name of effect i (static while cal lives). */
CDM_API size_t cdm_calibration_effect_count(const cdm_calibration *cal);
CDM_API const char *cdm_calibration_effect_name(const cdm_calibration *cal, size_t i);

/**
 * Applies a calibration to the device's poses from the next report on (the
 * library keeps its own copy; cal may be freed after). NULL returns to the
 * nominal model. Poses computed with a calibration carry CDM_POSE_COMPENSATED.
 * A calibration for another frame is refused (CDM_ERR_INVALID_ARG, the
 * text gives both values): its a_mm, b_mm and m_mm must each be the
 * device's (cdm_device_info) within 1 mm. Any thread.
 */
CDM_API int cdm_set_calibration(cdm_device *dev, const cdm_calibration *cal);

/**
 * The calibration stored in the device (feature reports 0x03/0x04, with
 * length and CRC-32). Read: *len receives the size; returns CDM_ERR_NO_MEM if
 * cap is too small (then *len says how much is needed), CDM_ERR_CRC when the
 * stored CRC does not match. Write: stores len bytes. Any thread; these talk
 * to the device and may block for some milliseconds.
 */
CDM_API int cdm_device_calibration_read(cdm_device *dev, char *buf, size_t cap, size_t *len);
CDM_API int cdm_device_calibration_write(cdm_device *dev, const char *data, size_t len);

/* ---------------------------------------------- experimental: model debugging
 * Define CDM_EXPERIMENTAL before including this header to use the functions
 * below. Their signatures may change in a minor release until they settle;
 * they are exported from the library all the same.
 */
#if defined(CDM_EXPERIMENTAL)

/**
 * Changes with every change to an experimental signature or struct. The
 * experimental symbols carry the ELF version node CDM_EXPERIMENTAL_<this>
 * (src/api/libcdm.map), so a program built against another experimental
 * version fails to load instead of calling a changed function.
 */
#define CDM_EXPERIMENTAL_VERSION 2

/**
 * A user-defined physical effect, acting on the cable readings. The model
 * calls `apply` with the readings predicted by the nominal geometry and every
 * effect before it; `apply` changes them in place (mm). Derivatives are taken
 * by central differences, so `apply` must be smooth in params and position.
 */
typedef int (*cdm_effect_apply_fn)(void *user, const double *params, const double position_mm[3],
                                   double readings_mm[4]);

/**
 * since 1.1: the same effect on n positions at once. positions_mm is n x 3
 * and readings_mm n x 4, row-major (position i's readings at
 * readings_mm[4 * i .. 4 * i + 3]), changed in place. Row i must come out as
 * `apply` would make it for position i alone (the rows are independent).
 * Non-zero fails the evaluation, as from `apply`.
 */
typedef int (*cdm_effect_apply_batch_fn)(void *user, const double *params, size_t n, const double *positions_mm,
                                         double *readings_mm);

/**
 * since 1.2: where a user effect acts (cdm_effect_def.stage).
 *  READING: on the readings, after the pot's transfer (ripple, drift,
 *    electronics): `values` are the readings the built-ins predict (mm).
 *  PATH: on the cable's length before the pot's transfer (sag, guides,
 *    pulleys): after the built-in Path stage (exit_pulley), before the
 *    built-in Transfer stage, so cable_stretch, cable_gain and the rest
 *    act on the length it returns: `values` are the four cables' lengths
 *    from anchor to holder (mm). Needs apply_geom.
 */
typedef enum cdm_effect_stage {
    CDM_EFFECT_STAGE_READING = 0,
    CDM_EFFECT_STAGE_PATH = 1
} cdm_effect_stage;

/**
 * since 1.2: what a geometry-aware user effect (cdm_effect_def.apply_geom)
 * sees of n positions. Every array is row-major, owned by the library and
 * valid during the call only; all in the device frame (cable plane y-z, x
 * out of the plane), mm. Cable c of position i is at [i][c]. The anchors and
 * holder points are those of the model being evaluated, after its geometry
 * effects (anchor_position, holder_geometry) at the current parameter
 * values (the fit moves them); without those effects, the drawing's.
 * struct_size is the library's: read only the fields your header has.
 */
typedef struct cdm_effect_context {
    uint32_t struct_size;
    uint32_t stage;              /**< cdm_effect_stage: what `values` holds */
    size_t n;                    /**< positions (rows) */
    const double *positions_mm;  /**< n x 3: the holder centre */
    const double *t_s;           /**< n: acquisition time, s since the session's start (0 for live poses) */
    const double *anchors_mm;    /**< n x 4 x 3: each cable's anchor (exit point) */
    const double *holders_mm;    /**< n x 4 x 3: each cable's attachment point on the holder */
    const double *unit;          /**< n x 4 x 3: unit vector from anchor to holder point */
    const double *chord_mm;      /**< n x 4: straight distance from anchor to holder point */
} cdm_effect_context;

/**
 * since 1.2: the effect on n positions with their geometry (ctx, whose n is
 * this n). values is n x 4, row-major, changed in place: the cable lengths
 * (PATH stage) or the readings (READING stage) so far. Row i must come out
 * the same whatever the other rows (they are independent); the rows come in
 * no promised order. Non-zero fails the evaluation, as from apply.
 */
typedef int (*cdm_effect_apply_geom_fn)(void *user, const double *params, size_t n, const cdm_effect_context *ctx,
                                        double *values);

typedef struct cdm_effect_def {
    uint32_t struct_size;
    uint32_t n_params;
    const char *name;              /**< unique, [a-z0-9_]+; copied */
    const char *doc;               /**< one paragraph: the physics; copied */
    const char *const *param_names;/**< n_params names; copied */
    const double *param_scale;     /**< typical magnitude of each parameter (for conditioning) */
    const double *lower;           /**< bounds, or NULL for +-1e3 * scale */
    const double *upper;
    cdm_effect_apply_fn apply;
    void *user;                    /**< passed to apply; must outlive the registration */
    /** since 1.1: the value each parameter starts from when the effect is
     *  added to a model (within [lower, upper]), or NULL for 0 clamped into
     *  the bounds. A parameter that enters non-linearly (a period, a centre,
     *  a time constant) is fitted from here; one named "period" is started
     *  by the diagnosis from the cable-length periodogram instead. */
    const double *initial;
    /** since 1.1: the effect on all positions at once, or NULL. At least one
     *  of apply, apply_batch and (since 1.2) apply_geom is given. Evaluations over many positions
     *  (the fit and its chi-squares, the diagnosis' candidate fits, the
     *  position solves behind their error statistics) call apply_batch, once
     *  per central-difference step (a position solve: once per iteration,
     *  its steps as rows) over every position, when it is given, else apply
     *  per position (a position solve that gets a non-zero return calls it
     *  again on each position's rows alone: only those fail). Evaluations at one
     *  position (cdm_get_pose, cdm_calibration_lengths) call apply, or
     *  apply_batch with n = 1 when only it is given. For an effect written
     *  in an interpreted language the batch form saves a call per position. */
    cdm_effect_apply_batch_fn apply_batch;
    /** since 1.2: each parameter's unit ("mm", "1/mm^2", "1" for a ratio),
     *  or NULL (no units). Copied; part of the effect's fingerprint. */
    const char *const *param_units;
    /** since 1.2: the geometry-aware form, or NULL. When given it is the
     *  only callback called (apply and apply_batch may be NULL), at every
     *  evaluation: over many positions at once where the fit and the
     *  diagnosis evaluate many, with n = 1 at one position (cdm_get_pose on
     *  the reader thread, cdm_calibration_lengths), where the library
     *  allocates nothing around the call. */
    cdm_effect_apply_geom_fn apply_geom;
    /** since 1.2: where the effect comes from, written with it into a
     *  calibration (so that loading one without the effect can say what to
     *  load): NULL, or e.g. "python:module". cdm_effect_load_plugin sets it
     *  to the plugin's absolute path for the effects its init registers. */
    const char *origin;
    /** since 1.2: cdm_effect_stage; 0 (READING) is the 1.1 behaviour.
     *  PATH needs apply_geom. */
    uint32_t stage;
} cdm_effect_def;

/**
 * Registers a user effect under def->name (in-process, for every later fit,
 * diagnosis and calibration load). CDM_ERR_INVALID_ARG names a clash with a
 * built-in. Any thread (the registry has its own lock); not from inside apply.
 * A struct_size of the 1.2 struct also checks the parameter names (each
 * non-empty, [A-Za-z_][A-Za-z0-9_]*, no two alike) and units (printable,
 * no '"' or '\\'), and a parameter whose lower bound is >= 0 is drawn
 * positive by the simulator's hidden effects (1.1 structs: a random sign,
 * clamped into the bounds). A calibration written with a user effect
 * records its origin and fingerprint (cdm_effect_fingerprint); loading it
 * needs the effect registered with the same fingerprint.
 */
CDM_API int cdm_effect_register(const cdm_effect_def *def);
CDM_API int cdm_effect_unregister(const char *name);

/**
 * Loads a plugin (a shared object exporting
 * `int cdm_plugin_init(int (*register_fn)(const cdm_effect_def *))`) and runs
 * its init, which registers its effects.
 */
CDM_API int cdm_effect_load_plugin(const char *path);

/** Number of effects known (built-in first, then user), and the name of effect i. */
CDM_API size_t cdm_effect_count(void);
CDM_API const char *cdm_effect_name(size_t i);

/**
 * since 1.2: effect i's fingerprint: 16 lowercase hex digits of the 64-bit
 * FNV-1a hash of its stage and its parameters' names and units (what a
 * calibration's values mean), NUL-terminated into buf (at least 17 bytes),
 * and its origin (cdm_effect_def.origin; "" for a built-in or none; lives
 * as long as the registration). NULL out-pointers are skipped. Any thread.
 */
CDM_API int cdm_effect_fingerprint(size_t i, char *buf, size_t len, const char **origin);

/** Progress of a long fit: stage text and fraction done. Return non-zero to cancel. */
typedef int (*cdm_progress_fn)(void *user, const char *stage, double fraction);

/**
 * Runs the model-debugging diagnosis (`cdm calib diagnose`) and returns its
 * result as JSON text (docs/calibration.md gives the schema), allocated by the
 * library: free it with cdm_free_string. `options_json` may be NULL or e.g.
 * {"effects": ["exit_pulley"], "jig_tolerance_mm": 0.03, "candidates": true,
 *  "per_position": true, "outliers": true, "calibration_out": "calib.json"}
 * ("outliers", since 1.1: positions the model and their neighbours both
 * disown are set aside and the diagnosis run again without them; false
 * keeps every position).
 * Errors name the file, line and column (cdm_thread_error). Any thread.
 * The dataset is streamed into per-position statistics (memory does not grow
 * with the samples per position) and read again during the call through the
 * descriptor opened first: replacing the file by rename meanwhile is
 * harmless; rewriting it in place makes the call fail (since 1.1).
 */
CDM_API int cdm_diagnose(const char *data_csv_path, const char *device_json_path,
                         const char *options_json, cdm_progress_fn progress, void *user,
                         char **result_json);

/* ---- cdm_fit (experimental, since 1.1) ----
 * Fits the calibration only: the effects in options_json fitted to the jig
 * data, without the diagnosis's candidates, review or validation (what
 * `cdm calib fit` needs). options_json: {"effects": [...] (required, not
 * empty: CDM_ERR_INVALID_ARG otherwise), "jig_tolerance_mm": mm (default:
 * estimated from the data), "outliers": true (default; false keeps every
 * position), "calibration_out": path (written atomically)}.
 * *result_json (free with cdm_free_string): {"effects": [{"name", "params":
 * {p: {value, std, unit}}}], "fit": {converged, chi2, dof, n_free,
 * evaluations, seconds, algorithm, message}, "jig_tolerance_mm": [x,y,z],
 * "nominal_error_mm" and "error_mm": {x,y,z} x {mean,std,rms,max},
 * "glitches": the samples set aside as the file was read, as the
 * diagnosis' data.glitches, "outliers": the positions the fitted model
 * and their neighbours both disown, set aside and the fit run again
 * without them, as the diagnosis' data.outliers}. Errors as
 * cdm_diagnose's. Any thread. */
CDM_API int cdm_fit(const char *data_csv_path, const char *device_json_path, const char *options_json,
                    cdm_progress_fn progress, void *user, char **result_json);

/* ---- cdm_calibration_position_covariance (experimental, since 1.2) ----
 * The covariance (mm^2, 3x3 row-major, device frame) of the position the
 * calibration gives at position_mm (device frame): its fitted parameters'
 * uncertainty (the file's fit.covariance, written by cdm_fit and by
 * cdm_diagnose's calibration_out) propagated to first order, at t = 0 s
 * for effects that drift in time. Its 1-sigma per axis is the square root
 * of the diagonal; the 95 % ellipsoid is {e : e' C^-1 e <= 7.815}.
 * CDM_ERR_UNSUPPORTED when the calibration carries no covariance,
 * CDM_ERR_NUMERIC where the model cannot place the position. Allocates:
 * not for the haptic path. Any thread. */
CDM_API int cdm_calibration_position_covariance(const cdm_calibration *cal, const double position_mm[3],
                                                double cov_mm2[9]);

/* ---- cdm_plan (experimental, since 1.2) ----
 * Plans a jig session before any data (`cdm calib plan`): which of the
 * plate's positions (holes x heights) to measure, from the geometry and the
 * catalogue alone. options_json: {"positions": N (required), "samples": per
 * position (100), "holes": per side (25), "pitch_mm" (5), "heights_mm"
 * ([30,40,50,60,70]), "effects": the model to plan for (default: every
 * built-in effect on the cables' geometry, path and pots), "noise_mm":
 * per-sample pot noise (0.05), "jig_tolerance_mm": each visit's seating
 * error (0.03), "alpha" (1e-3), "power" (0.9), "device": device JSON path
 * (default: the nominal), "measured": positions already measured ([x, y,
 * z] or a plan's [x, y, z, samples] rows, mm, each a hole of the plate at
 * one of its heights: in the design from the start, and "positions" more
 * are chosen: a session planned on from the data so far), "allowed": the
 * only positions that may be chosen (same form)}. First, while an effect's
 * likelihood-ratio test against the nominal model has power below "power"
 * at its typical size (and the whole plate reaches it), the position adding
 * most to the weakest one's non-centrality; then greedy I-optimal picks (the
 * predicted position variance averaged over the plate's box at every
 * height).
 * *result_json (free with cdm_free_string): {"positions": [[x_ref, y_ref,
 * z_ref, samples]] in walking order (height by height, rows along y, back
 * and forth along z), "points": their point ids in the whole plate's plan,
 * "samples", "plate_positions", "measured" (count), "design": {effects,
 * excluded [{effect, why}], detectability_picks}, "predicted_sigma_mm":
 * {plan (the measured positions with the chosen), whole_plate},
 * "detectability": [{effect, dof, lambda, power, lambda_whole_plate,
 * power_whole_plate, detectable, reachable}], "test", "alpha",
 * "target_power", "order"}. CDM_ERR_INVALID_ARG names a bad option, a
 * position that is no hole, or more positions than are left to choose
 * from. Any thread. */
CDM_API int cdm_plan(const char *options_json, cdm_progress_fn progress, void *user, char **result_json);

/* ---- cdm_check (experimental, since 1.2) ----
 * Checks a calibration (cdm_fit's calibration_out) on another jig session
 * of the same device, without refitting it: the calibration as it is, with
 * only the jig placed anew (its Jig-stage effects, jig_misalignment added
 * at zero when it has none, and the fixture heights' offsets: a jig is
 * placed by hand at every session), the noise model estimated from this
 * data as cdm_fit's is. The device is the calibration's own. options_json
 * (NULL: defaults): {"jig_tolerance_mm": mm (default: estimated),
 * "max_error_mm": mm (positions whose mean error is longer are listed;
 * default: none)}. *result_json (free with cdm_free_string): {"tool": "cdm
 * calib check", "effects":
 * the calibration's (its Jig-stage ones apart), "positions": count, "jig":
 * {re_estimated, text, effects: [{name, params: {p: {value, std, unit}}}],
 * added, fixture_mm, tolerance_mm, plate_holes_mm}, "error_mm" and
 * "nominal_error_mm": {x,y,z} x {mean,std,rms,max} per sample (the seed's
 * Table 1), "position_error_mm": {x,y,z} x {mean,rms,max} of each position's
 * mean error (the calibration's systematic error, the noise averaged out),
 * "calibration_fit": {data, error_mm: {x,y,z: {rms}}} from the calibration's
 * "fit" block or null, "failing": {count, test, positions: [{point, ref,
 * error_mm}], beyond_max_error (with max_error_mm)}, "predicted":
 * {available, calibration_rms_mm, noise_and_jig_rms_mm, chi2_per_dof,
 * p_value, as_predicted, test, text, per_position: {ref_mm, error_mm,
 * calibration_sigma_mm, expected_sigma_mm, chi2}} (the error against the
 * calibration's own covariance, cdm_calibration_position_covariance's;
 * per_position: each placed position's), "model_check": {holds,
 * chi2_per_dof, chi2_p_value, chi2_scale, structure, test, text},
 * "reading_noise_mm", "glitches"}. Errors as cdm_diagnose's (the
 * calibration's: CDM_ERR_IO unreadable, CDM_ERR_PARSE malformed or naming
 * an effect not registered). Any thread. */
CDM_API int cdm_check(const char *data_csv_path, const char *calibration_json_path, const char *options_json,
                      cdm_progress_fn progress, void *user, char **result_json);

/** Frees a string returned by libcdm. NULL is fine. */
CDM_API void cdm_free_string(char *s);

/* ------------------------------------------ since 1.1: the one dataset writer
 * Writes a jig dataset CSV (point,x_ref,y_ref,z_ref,l1,l2,l3,l4) atomically:
 * rows go to an exclusive temporary beside `path`; commit fsyncs it and
 * renames it over `path`. Freed without commit: no file, the old one intact.
 * `path` must not be a special file nor one of `protect_paths` (the caller's
 * own inputs; n_protect may be 0). Errors carry the errno text
 * (cdm_thread_error). One writer per thread at a time; free accepts NULL.
 * Numbers are written with four decimals and '.' whatever the locale.
 */
typedef struct cdm_dataset_writer cdm_dataset_writer;
CDM_API int cdm_dataset_writer_open(const char *path, const char *const *protect_paths, size_t n_protect,
                                    cdm_dataset_writer **out);
/* One sample: the jig position's id and reference (mm, jig frame) and the
 * four cable lengths (mm). A row the dataset reader would refuse is refused
 * here, CDM_ERR_INVALID_ARG, with a text naming the point, the argument
 * (ref_mm[k] / lengths_mm[k]) and its value: a NaN or infinite value, a
 * reference beyond +-5000 mm, a length outside (0, 10000] mm as the file
 * would hold it (1e-5 is written 0.0000: refused), a point whose reference
 * differs from its first row's (as written). Such a refused row writes
 * nothing and the writer goes on. Also CDM_ERR_INVALID_ARG: any add after
 * cdm_dataset_writer_commit ("already committed"). CDM_ERR_IO: a write
 * failed (ENOSPC, EIO, EFBIG); the file is then abandoned and every later
 * add and the commit fail with CDM_ERR_IO and that first failure's text. */
CDM_API int cdm_dataset_writer_add(cdm_dataset_writer *w, int point, const double ref_mm[3],
                                   const double lengths_mm[4]);
/* A row with its acquisition time (s since the session's start, finite):
 * the file then has a t_s column, which drift over the session is measured
 * against (docs/calibration.md). A file's rows are all timed or all not:
 * mixing the two calls is CDM_ERR_INVALID_ARG (a refused row decides
 * nothing). Otherwise as cdm_dataset_writer_add. */
CDM_API int cdm_dataset_writer_add_at(cdm_dataset_writer *w, int point, const double ref_mm[3],
                                      const double lengths_mm[4], double t_s);
/* Writes the rest, fsyncs and renames over `path`. Once only: a second
 * commit is CDM_ERR_INVALID_ARG ("already committed"); so is a commit with
 * no row added ("no row was added": the reader would refuse such a file,
 * and it would replace what `path` held), which writes nothing and leaves
 * the writer open for rows; after an add or commit that failed with CDM_ERR_IO, that
 * error again with the first failure's text. The writer still needs
 * cdm_dataset_writer_free. */
CDM_API int cdm_dataset_writer_commit(cdm_dataset_writer *w);
CDM_API void cdm_dataset_writer_free(cdm_dataset_writer *w);

/* ------------------------------------------------- experimental: tools (since 1.1)
 * What the `cdm` command needs beyond the stable API. Experimental: see
 * CDM_EXPERIMENTAL_VERSION. Every function sets cdm_thread_error() when it
 * fails.
 */

/**
 * The device-info feature report (ID 0x02) of an open device, byte for byte,
 * report ID first, as the device sent it (a recording starts with it). *len
 * receives its size; CDM_ERR_NO_MEM when buf is NULL or cap too small (then
 * *len says how much is needed). Caller owns buf. Any thread; talks to the
 * device and may block for some milliseconds.
 */
CDM_API int cdm_device_info_report(cdm_device *dev, uint8_t *buf, size_t cap, size_t *len);

/**
 * The position (device frame, mm) the simulated master truly had when it sent
 * report `sequence` (cdm_pose.sequence), for measuring the driver's error.
 * CDM_ERR_UNSUPPORTED when dev is not a sim: device or the report is older
 * than the simulator remembers (16384 reports). Any thread, including the
 * on_sample callback; does not block on the reader.
 */
CDM_API int cdm_sim_truth(cdm_device *dev, uint32_t sequence, double position_mm[3]);

/**
 * A recording for `replay:FILE` (docs/protocol.md, "Replay files"; MCAP and
 * CSV: docs/recording.md): opened with the device-info report
 * (cdm_device_info_report), then every input report with its host receipt
 * time (cdm_sample.raw->host_time_ns, report and report_len). The handle is
 * the caller's until cdm_recorder_close, which flushes, completes (MCAP: the
 * summary and footer), closes and frees it (NULL is fine) and reports a
 * failure to complete the file. `path` must not exist. One thread at a time
 * per recorder (the caller serialises); write may be called from the
 * on_sample callback. cdm_recorder_open picks the format by the extension:
 * ".mcap" MCAP, ".csv" a CSV of poses, anything else the replay format.
 * The device-info report is checked by the parser replay: checks it with,
 * before the file is created, whatever the format: NULL, empty (len 0),
 * longer than 1024 bytes, or rejected by the parser (too short, wrong report
 * ID or protocol version, a field out of range) is CDM_ERR_INVALID_ARG with
 * a text naming what is wrong.
 */
typedef struct cdm_recorder cdm_recorder;
CDM_API int cdm_recorder_open(const char *path, const uint8_t *info_report, size_t len, cdm_recorder **out);
/** since 1.1: `format` "cdmrec", "mcap" or "csv" whatever the name (a
 *  temporary's), or NULL for the extension's. MCAP's chunks are compressed
 *  with zstd; "mcap:lz4" and "mcap:none" choose lz4 or none ("mcap:zstd"
 *  says the default). */
CDM_API int cdm_recorder_open_ex(const char *path, const char *format, const uint8_t *info_report, size_t len,
                                 cdm_recorder **out);
/** The report only: MCAP gets no pose for it, a CSV refuses it
 *  (CDM_ERR_INVALID_ARG). Host times never decrease in a recording (replay:
 *  refuses a file where one does): a host_time_ns before the previous
 *  record's is CDM_ERR_INVALID_ARG naming both, nothing is written and the
 *  recorder goes on; an equal time is fine. The report's bytes (1..1024)
 *  are kept as received, malformed or not: a replay counts them as a live
 *  device's (cdm_stats.malformed), as the recorded device did. After a
 *  write error (CDM_ERR_IO) no later write succeeds. */
CDM_API int cdm_recorder_write(cdm_recorder *rec, uint64_t host_time_ns, const uint8_t *report, size_t len);
/** since 1.1: one on_sample sample: its report at source_time_ns and (MCAP,
 *  CSV) its pose. Times as cdm_recorder_write's, in every format. */
CDM_API int cdm_recorder_write_sample(cdm_recorder *rec, const cdm_sample *sample);
/** since 1.2: one on_rejected report, its bytes at source_time_ns as
 *  cdm_recorder_write's, so a replay discards it as the live reader did and
 *  its counters come out the same; MCAP also logs the reason (channel
 *  `/cdm/rejected`). A CSV, which holds poses only, skips it (CDM_OK). */
CDM_API int cdm_recorder_write_rejected(cdm_recorder *rec, const cdm_rejected *rejected);
CDM_API int cdm_recorder_close(cdm_recorder *rec);

/**
 * The ordered jig plan of a calibration session (`cdm record --jig`):
 * holes per side (default 25), hole pitch in mm (default 5), fixture heights
 * in mm (default 30,40,50,60,70; copied), samples kept per position (default
 * 100); a zero (or NULL/0 heights) keeps the default. With a sim: URI whose
 * motion is jig, the simulator's own jig_* options are the defaults, and
 * values that contradict them are CDM_ERR_INVALID_ARG (the labels would not
 * match the positions); uri may be NULL. Values are validated
 * (CDM_ERR_INVALID_ARG naming the field). The plan is the caller's: free it
 * with cdm_jig_plan_free (NULL is fine). Any thread; once made (and, for a
 * planned session, given its file by cdm_jig_plan_use_file) a plan is
 * read-only, so several threads may read it.
 */
typedef struct cdm_jig_plan cdm_jig_plan;
CDM_API int cdm_jig_plan_create(const char *uri, int holes, double pitch_mm, const double *heights_mm,
                                size_t n_heights, int samples, cdm_jig_plan **out);
CDM_API size_t cdm_jig_plan_count(const cdm_jig_plan *plan);
/** Samples to keep at each position (of the whole plate; a planned
 *  session's own are cdm_jig_plan_samples_at's). */
CDM_API int cdm_jig_plan_samples(const cdm_jig_plan *plan);
/**
 * since 1.2: a planned session (`cdm calib plan`'s PLAN.csv: x_ref, y_ref,
 * z_ref, samples per row): the plan becomes the file's positions, in its
 * order, each a hole of the plate at one of its heights (within 1e-6 mm)
 * with its own samples. A sim: URI with jig_plan= set does this in
 * cdm_jig_plan_create; another file then is CDM_ERR_INVALID_ARG (the labels
 * would not match the positions), and so is any file for a sim: URI without
 * jig_plan= (it walks the whole plate). CDM_ERR_INVALID_ARG naming the file,
 * line and fault, or the first row that is no hole; the plan is unchanged
 * then. It changes the plan: not concurrently with another call on the same
 * plan; any thread otherwise.
 */
CDM_API int cdm_jig_plan_use_file(cdm_jig_plan *plan, const char *plan_csv);
/**
 * since 1.2: a PLAN.csv's rows as a JSON array of [x_ref, y_ref, z_ref,
 * samples] (mm, jig frame), for cdm_simulate_jig_dataset's "plan" option.
 * CDM_ERR_INVALID_ARG naming the file, line and fault. Free *rows_json with
 * cdm_free_string. Any thread.
 */
CDM_API int cdm_plan_file_read(const char *plan_csv, char **rows_json);
/** since 1.2: samples to keep at position i (0 for an i past the end). Any thread. */
CDM_API int cdm_jig_plan_samples_at(const cdm_jig_plan *plan, size_t i);
/**
 * since 1.2: the plate the plan's positions are holes of: holes per side,
 * pitch (mm) and the fixture heights (mm, up to cap of them into heights_mm;
 * *n_heights says how many there are: call again with more room when it is
 * over cap). What cdm_plan's "holes", "pitch_mm" and "heights_mm" take.
 * NULL out-pointers are skipped (heights_mm with cap 0). Any thread.
 */
CDM_API int cdm_jig_plan_plate(const cdm_jig_plan *plan, int *holes, double *pitch_mm, double *heights_mm,
                               size_t cap, size_t *n_heights);
/** Position i: its dataset `point` id and reference x (height), y, z in mm, jig frame. */
CDM_API int cdm_jig_plan_get(const cdm_jig_plan *plan, size_t i, int *point, double ref_mm[3]);
CDM_API void cdm_jig_plan_free(cdm_jig_plan *plan);

/**
 * The effect catalogue (cdm_effect_count order): the physics in one paragraph
 * and each parameter (NULL out-pointers are skipped). Strings live as long as the effect is registered
 * (built-ins: forever); do not free them. Any thread.
 */
CDM_API const char *cdm_effect_doc(size_t i);
CDM_API size_t cdm_effect_param_count(size_t i);
/** Parameter k of effect i: name, unit, typical magnitude, bounds of the fit. */
CDM_API int cdm_effect_param(size_t i, size_t k, const char **name, const char **unit, double *scale,
                             double *lower, double *upper);

/**
 * The nominal device description (a = b = 150, m = 30 mm: the geometry
 * cdm_simulate_jig_dataset and `cdm calib diagnose` use without a device
 * JSON), as device JSON text allocated by the library: free it with
 * cdm_free_string. Any thread.
 */
CDM_API int cdm_nominal_device_json(char **json);
/**
 * since 1.2: a device description JSON file read and checked as
 * cdm_diagnose reads its device_json_path (a file that cannot be read:
 * CDM_ERR_IO; unknown keys, ranges, a frame that is no frame:
 * CDM_ERR_INVALID_ARG with "file:line:col: ..." in cdm_thread_error()),
 * given back as the device
 * JSON text cdm_nominal_device_json gives (every field, defaults filled
 * in). Free it with cdm_free_string. Any thread.
 */
CDM_API int cdm_device_file_read(const char *device_json_path, char **json);

/**
 * The options of cdm_simulate_jig_dataset with their defaults, as JSON text
 * allocated by the library (free it with cdm_free_string). Any thread.
 */
CDM_API int cdm_simulate_jig_defaults(char **options_json);

/**
 * Writes a simulated jig dataset CSV (`cdm calib simulate`: the seed's
 * experiment in software) from a known model. options_json may be NULL or
 * hold any of: holes, pitch_mm, heights_mm [..], samples, noise_mm, quant_mm,
 * jig_tolerance_mm (each visit's own seating error), jig_hole_mm (each
 * plate hole's y, z error, shared by every height; since 1.1), jig_fixture_mm
 * (each height's x error, shared by every hole; since 1.1), seed,
 * effect_seed (numbers); device (device JSON path;
 * default the nominal geometry), truth (calibration JSON as the true model),
 * effects [..] (hidden effects with random realistic magnitudes), truth_out
 * (where to write the true model), plan [[x_ref, y_ref, z_ref, samples], ..]
 * (since 1.2: only these positions of the plate, in this order, each a
 * hole at one of the heights; cdm_plan's "positions"). An unknown key or a bad value is
 * CDM_ERR_INVALID_ARG naming it; other errors name the file. Any thread.
 */
CDM_API int cdm_simulate_jig_dataset(const char *out_csv, const char *options_json);

/**
 * Writes `len` bytes to `path` the way libcdm writes every file: an exclusive
 * temporary in the target's directory, fsync, rename over the target, fsync
 * of the directory. The old target survives any failure; a target that is
 * not a regular file, or is the same file as one of `protect_paths` (the
 * caller's inputs; n_protect may be 0), is refused (CDM_ERR_IO naming it).
 * Errors carry the errno text. Any thread.
 */
CDM_API int cdm_write_file_atomic(const char *path, const void *data, size_t len, const char *const *protect_paths,
                                  size_t n_protect);

/* --------------------------------------- experimental: hot-plug (since 1.1)
 * Arrivals and departures of masters (USB 1209:cd01 hidraw nodes, what
 * cdm_enumerate lists), as events from udev's monitor: no polling. Linux
 * only; where udev's netlink socket is refused (a sandbox) cdm_watch fails
 * with CDM_ERR_UNSUPPORTED, and where no udevd runs (a bare container) no
 * event ever comes. docs/reliability.md, "Hot-plug", says why udev and not
 * libusb's hotplug callback. Experimental until it has run against a real
 * master (it is tested on the emulated kernel device, docs/testing.md).
 */

/** cdm_watch_event.kind. */
typedef enum cdm_watch_kind {
    CDM_WATCH_ARRIVED = 1, /**< a master's node appeared (or was there at the start, CDM_WATCH_ENUMERATE) */
    CDM_WATCH_LEFT = 2     /**< it went away (unplugged) */
} cdm_watch_kind;

/** cdm_watch flags. */
enum cdm_watch_flag {
    /** Report the masters already connected as arrivals first (as libusb's
     *  LIBUSB_HOTPLUG_ENUMERATE), so that the callback alone keeps a list. */
    CDM_WATCH_ENUMERATE = 1u << 0
};

/** One arrival or departure. Valid only during the callback. */
typedef struct cdm_watch_event {
    uint32_t struct_size;
    uint32_t kind;                /**< cdm_watch_kind */
    uint64_t host_time_ns;        /**< CLOCK_MONOTONIC when the watcher noticed it */
    const cdm_device_info *info;  /**< the master, as cdm_enumerate gives it (uri "hid:/dev/hidrawN",
                                   *   serial, and firmware and the rest when it answered its info
                                   *   report); for CDM_WATCH_LEFT, what was known when it arrived.
                                   *   Its struct_size is the library's: read only the fields your
                                   *   header has. */
} cdm_watch_event;

/**
 * Called on the watcher's own thread (one per cdm_watcher), one event at a
 * time, in the order noticed; never after cdm_watch_free returned. It may
 * call any cdm_* function (cdm_open of the arrived uri, for one) except
 * cdm_watch_free on its own watcher, which would have to join the thread it
 * runs on: that call is refused (logged at CDM_LOG_ERROR, the watcher keeps
 * running). While it runs, further events wait in the kernel's socket
 * buffer: keep it short.
 */
typedef void (*cdm_watch_fn)(void *user, const cdm_watch_event *event);

typedef struct cdm_watcher cdm_watcher;

/**
 * Starts watching: `fn(user, event)` for every master that arrives or
 * leaves from now on (and, with CDM_WATCH_ENUMERATE, for every one present
 * first). Returns once subscribed: a master plugged in after cdm_watch
 * returns is reported. CDM_ERR_INVALID_ARG for a NULL fn or out or an
 * unknown flag; CDM_ERR_UNSUPPORTED where udev's monitor is refused
 * (cdm_thread_error says why). An open device needs no watcher to
 * reconnect: its reader wakes on the same events by itself. Any thread.
 */
CDM_API int cdm_watch(uint32_t flags, cdm_watch_fn fn, void *user, cdm_watcher **out);

/**
 * Stops the watcher and frees it; when it returns no callback is running
 * and none will. NULL is fine. Any thread except the watcher's own (from
 * its callback the call is refused, see cdm_watch_fn).
 */
CDM_API void cdm_watch_free(cdm_watcher *watcher);

#endif /* CDM_EXPERIMENTAL */

#ifdef __cplusplus
}
#endif

#endif /* CDM_CDM_H */
