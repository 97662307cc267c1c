// The Java message types from the jar (what lcm-spy loads): encode a profile and a status, decode
// them back, and check every field. Run by ctest with lcm.jar and laserline-lcmtypes.jar.
import java.io.ByteArrayOutputStream;
import java.io.DataOutputStream;
import java.io.IOException;
import laserline.point_t;
import laserline.profile_t;
import laserline.status_t;

public class LcmTypesJarTest {
  static void check(boolean ok, String what) {
    if (!ok) {
      System.err.println("LcmTypesJarTest: FAILED: " + what);
      System.exit(1);
    }
  }

  static byte[] encode(lcm.lcm.LCMEncodable message) throws IOException {
    ByteArrayOutputStream bytes = new ByteArrayOutputStream();
    message.encode(new DataOutputStream(bytes));
    return bytes.toByteArray();
  }

  public static void main(String[] args) throws IOException {
    profile_t p = new profile_t();
    p.utime = 1700000000123456L;
    p.sequence = 42;
    p.detector = "maxvalue";
    p.laser_on = true;
    p.width = 1280;
    p.height = 1024;
    p.search_axis = profile_t.SEARCH_ROWS;
    p.search_line_step = new double[] {0, 1};
    p.search_along = new double[] {1, 0};
    p.num_points = 2;
    p.instance_id = -42L;
    p.points = new point_t[2];
    for (int i = 0; i < 2; ++i) {
      p.points[i] = new point_t();
      p.points[i].u = (short) (100 + i);
      p.points[i].v = 511.25f + i;
      p.points[i].segment = -1;
      p.points[i].valid = true;
      p.points[i].xyz = new float[] {Float.NaN, Float.NaN, Float.NaN};
    }
    profile_t back = new profile_t(encode(p));
    check(back.sequence == 42 && back.utime == p.utime, "profile header");
    check(back.detector.equals("maxvalue") && back.laser_on, "profile detector and laser");
    check(back.search_axis == profile_t.SEARCH_ROWS && back.search_line_step[1] == 1.0
              && back.search_along[0] == 1.0 && back.search_origin[0] == 0.0,
          "profile search axes");
    check(back.num_points == 2 && back.points[1].u == 101 && back.points[1].v == 512.25f,
          "profile points");
    check(back.instance_id == p.instance_id, "profile instance id");

    status_t s = new status_t();
    s.camera_backend = "sim";
    s.detector = "maxvalue";
    s.camera_state = "streaming";
    s.frames_processed = 301;
    s.cpu_percent = 23.5f;
    s.bad_messages = 7;
    s.bad_frames = 2;
    s.instance_id = 0x7eadbeef12345678L;
    s.strobe_state = "ok";
    status_t sb = new status_t(encode(s));
    check(sb.frames_processed == 301 && sb.cpu_percent == 23.5f, "status");
    check(sb.bad_messages == 7 && sb.bad_frames == 2 && sb.instance_id == 0x7eadbeef12345678L,
          "status input counters and instance id");
    check(sb.strobe_state.equals("ok"), "status strobe_state");
    check(profile_t.LCM_FINGERPRINT != status_t.LCM_FINGERPRINT, "fingerprints");
    System.out.println("LcmTypesJarTest: profile_t and status_t round-trip through the jar");
  }
}
